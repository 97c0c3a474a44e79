#!/usr/bin/env python3
"""Watch a running team: one line per tick with its smallest separation, computed here.

How to run (iceoryx2 0.10 from PyPI, e.g. the test venv of scripts/test-deps.sh):

  Terminal 1:  target/release/orchestrator launch --team demo --t-total 600
  Terminal 2:  .venv/bin/python python/examples/watch.py --team demo

Prints `tick <k> t <seconds> min_separation <metres> agents <i> <j>` per complete tick; ends
when the team has been silent for --silence seconds after its first tick (or after --ticks
lines); exit 2 when the team does not appear, 3 when it shows no tick, within --join seconds.
"""

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import cdm_bus  # noqa: E402


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--team", required=True, help="the team's name (launch --team)")
    p.add_argument("--dt", type=float, default=0.01, help="the scenario's tick length in seconds")
    p.add_argument("--ticks", type=int, default=0, help="stop after this many lines (0: no limit)")
    p.add_argument("--join", type=float, default=30.0, help="seconds to wait for the team to appear")
    p.add_argument("--silence", type=float, default=3.0, help="seconds without a tick before ending")
    a = p.parse_args()

    deadline = time.monotonic() + a.join
    while True:
        try:
            reader = cdm_bus.TeamReader(a.team, node_name=f"watch-{os.getpid()}")
            break
        except Exception as e:  # the team is not there yet, or still creating its services
            if time.monotonic() > deadline:
                print(f"watch: team {a.team}: {e}", file=sys.stderr)
                return 2
            time.sleep(0.2)

    printed = 0
    last_tick_at = time.monotonic()
    while True:
        for tick, states in reader.poll():
            d, i, j = cdm_bus.min_separation(states)
            print(f"tick {tick} t {tick * a.dt:.2f} min_separation {d!r} agents {i} {j}", flush=True)
            printed += 1
            last_tick_at = time.monotonic()
            if a.ticks and printed >= a.ticks:
                return 0
        # Before the first tick the team may still be starting: wait up to --join for it.
        if printed and time.monotonic() - last_tick_at > a.silence:
            return 0
        if not printed and time.monotonic() > deadline:
            print(f"watch: team {a.team}: no complete tick within {a.join} s", file=sys.stderr)
            return 3
        reader.wait(0.005)


if __name__ == "__main__":
    sys.exit(main())
