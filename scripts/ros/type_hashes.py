"""Prints the RIHS01 type hash `rosbags` computes for each type named on
the command line (Jazzy definitions; irobot_create_msgs as check_bag.py
defines it), as one JSON object.

usage: type_hashes.py TYPE [TYPE ...]
"""

import json
import sys

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from check_bag import IROBOT

store = get_typestore(Stores.ROS2_JAZZY)
for name, text in IROBOT.items():
    store.register(get_types_from_msg(text, name))
json.dump({t: store.hash_rihs01(t) for t in sys.argv[1:]}, sys.stdout)
