"""Headless ir-sim throughput: prints `irsim_steps_per_s <float>` on stdout.

Benchmark setup (twindrive's bench/irsim_setup*.toml must describe the same):
- World: 10 m x 10 m square room, boundary walls at x=0, x=10, y=0, y=10.
- Six static obstacles:
    circles centred (3,3) r=0.5, (7,3) r=0.6, (5,7) r=0.5;
    axis-aligned rectangles centred (2,7) 1.0x0.6, (8,7) 0.8x0.8, (5,4.5) 1.2x0.4.
- One differential-drive robot, circular footprint r=0.2 m, start pose
  (1.5, 5.0, heading 0), constant command v=0.2 m/s, omega=0.4 rad/s
  (drives a small circle around (1.5, 5.5) and never touches anything).
- Step time 0.1 s.
- world.yaml: one 2D lidar on the robot, 360 beams over 360 degrees (1 degree
  apart), range_min 0, range_max 8 m, no noise.
- world_nosensor.yaml: the same without any sensor.

Only the stepping loop is timed (time.perf_counter); warm-up steps are not.
Everything but the result line goes to stderr.
"""

import argparse
import contextlib
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ACTION = [0.2, 0.4]  # [v m/s, omega rad/s], differential drive


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=2000, help="timed steps")
    ap.add_argument("--warmup", type=int, default=100, help="untimed steps first")
    ap.add_argument("--no-sensor", action="store_true", help="robot without lidar")
    args = ap.parse_args()

    world = os.path.join(HERE, "world_nosensor.yaml" if args.no_sensor else "world.yaml")
    os.environ.setdefault("MPLBACKEND", "Agg")

    # irsim prints its matplotlib backend probing at import time and its
    # loguru console sink writes to stdout: keep stdout for the result line.
    with contextlib.redirect_stdout(sys.stderr):
        import irsim

        # headless=True: no figure, no window, no keyboard/mouse, no animation.
        env = irsim.make(world, headless=True, log_level="WARNING")

        assert len(env.obstacle_list) == 7, "walls + 6 obstacles expected"
        assert env.robot_number == 1
        sensors = env.robot.sensors
        if args.no_sensor:
            assert not sensors, "no-sensor variant must have no sensor"
        else:
            assert len(sensors) == 1
        for _ in range(args.warmup):
            env.step(ACTION)
        if not args.no_sensor:
            scan = env.get_lidar_scan()
            assert len(scan["ranges"]) == 360, len(scan["ranges"])
            assert scan["ranges"].min() > 0.2 and scan["ranges"].max() == 8.0

        t0 = time.perf_counter()
        for _ in range(args.steps):
            env.step(ACTION)
        elapsed = time.perf_counter() - t0

        assert not env.robot.collision and env.status == "Running", env.status
        print(
            f"ir-sim {irsim.__version__} {os.path.basename(world)}: {args.steps} steps "
            f"in {elapsed:.3f} s, final state {env.robot.state.ravel().round(3)}",
            file=sys.stderr,
        )

    print(f"irsim_steps_per_s {args.steps / elapsed:.1f}")


if __name__ == "__main__":
    main()
