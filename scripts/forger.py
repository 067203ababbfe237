"""An attacker on the zenoh network, independent of twindrive: publishes
payloads it was given (forged messages, or genuine ones it captured
earlier) on a key expression, and captures what others publish.

  forger.py publish ENDPOINT KEY FILE [--every S] [--for S]
      each payload of FILE in turn (again from the first when all went),
      one every S seconds (default 0.25), for S seconds (default: once)
  forger.py capture ENDPOINT KEY FILE --for S
      every payload published on KEY for S seconds, appended to FILE

FILE holds payloads as a 4-byte big-endian length and the bytes. A zenoh
client of ENDPOINT (a robot's or a master's listening port, or a router);
over TLS (`tls/HOST:PORT`) with --ca (the CA it checks the router by) and,
to show one, --cert and --private-key (a client certificate). Says one line when
it starts and one when it ends, on stderr; exits 3 if it cannot connect.
"""

import argparse
import struct
import sys
import time

import zenoh


def read_payloads(path):
    data = open(path, "rb").read()
    out, i = [], 0
    while i < len(data):
        (n,) = struct.unpack(">I", data[i : i + 4])
        out.append(data[i + 4 : i + 4 + n])
        i += 4 + n
    return out


def session(a):
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", f'["{a.endpoint}"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    if a.ca:
        conf.insert_json5("transport/link/tls/root_ca_certificate", f'"{a.ca}"')
    if a.cert:
        conf.insert_json5("transport/link/tls/connect_certificate", f'"{a.cert}"')
        conf.insert_json5("transport/link/tls/connect_private_key", f'"{a.private_key}"')
        conf.insert_json5("transport/link/tls/enable_mtls", "true")
    try:
        return zenoh.open(conf)
    except Exception as e:  # zenoh's own error type
        print(f"forger: cannot connect to {a.endpoint}: {e}", file=sys.stderr, flush=True)
        sys.exit(3)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("mode", choices=["publish", "capture"])
    p.add_argument("endpoint")
    p.add_argument("key")
    p.add_argument("file")
    p.add_argument("--every", type=float, default=0.25)
    p.add_argument("--for", dest="duration", type=float, default=None)
    p.add_argument("--ca")
    p.add_argument("--cert")
    p.add_argument("--private-key", dest="private_key")
    a = p.parse_args()
    s = session(a)
    if a.mode == "publish":
        payloads = read_payloads(a.file)
        pub = s.declare_publisher(a.key)
        time.sleep(0.5)  # let the route to the subscriber form
        print(f"forger: publishing {len(payloads)} payload(s) on {a.key}", file=sys.stderr, flush=True)
        start, sent = time.monotonic(), 0
        while True:
            pub.put(payloads[sent % len(payloads)])
            sent += 1
            if a.duration is None and sent >= len(payloads):
                break
            if a.duration is not None and time.monotonic() - start >= a.duration:
                break
            time.sleep(a.every)
        print(f"forger: published {sent}", file=sys.stderr, flush=True)
    else:
        got = []
        sub = s.declare_subscriber(a.key, lambda sample: got.append(bytes(sample.payload.to_bytes())))
        print(f"forger: capturing {a.key}", file=sys.stderr, flush=True)
        time.sleep(a.duration or 10.0)
        sub.undeclare()
        with open(a.file, "ab") as f:
            for b in got:
                f.write(struct.pack(">I", len(b)) + b)
        print(f"forger: captured {len(got)}", file=sys.stderr, flush=True)
    s.close()


if __name__ == "__main__":
    main()
