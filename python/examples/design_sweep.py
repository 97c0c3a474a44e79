#!/usr/bin/env python3
"""Design a formation, certify it, sweep its travel time and plot the deviation against T.

A notebook in script form for the `cdm` package (`pip install ./python`). How to run:

  python3 -m venv /tmp/cdm && /tmp/cdm/bin/pip install ./python
  /tmp/cdm/bin/python python/examples/design_sweep.py --out /tmp/design

Three leaders carry a triangle of followers from one place to another (Sec. III); the script
prints the certificate, then `T <seconds> deviation <metres>` for each travel time of the sweep
and `T_threshold <seconds>`, writes the designed scenario (design.toml) and the sweep
(sweep.csv) into --out, and draws sweep.png there when matplotlib is installed.
"""

import argparse
import os
import sys

import numpy as np

import cdm

# The leaders: the triangle's corners now and at the goal (metres; z up). The goal is the
# triangle moved, turned and shrunk: an affine map, as continuum deformation is (eq. 13).
LEADERS = [
    ((0.0, 0.0, 100.0), (400.0, 300.0, 80.0)),
    ((120.0, 0.0, 100.0), (490.0, 330.0, 80.0)),
    ((60.0, 100.0, 110.0), (420.0, 390.0, 88.0)),
]


def followers(rows):
    """Follower positions inside the leaders' triangle: barycentric weights on a grid, every
    weight at least 1 / (rows + 2), so each follower sits well inside."""
    corners = np.array([start for start, _ in LEADERS])
    points = []
    n = rows + 2
    for i in range(1, n):
        for j in range(1, n - i):
            k = n - i - j
            weights = np.array([i, j, k], dtype=float) / n
            points.append(weights @ corners)
    return points


def design(rows, t_total_s):
    """The scenario as TOML text: what a scenario file would hold."""
    lines = [
        'name = "designed-triangle"',
        f"t_total_s = {t_total_s!r}",
        "eps_m = 1.0",
        "comm_hz = 100.0",
        "gains = [8.0, 24.0, 51.5625, 23.4375]",
    ]
    ident = 0
    for start, goal in LEADERS:
        ident += 1
        lines += ["", "[[agents]]", f"id = {ident}", 'role = "primary"',
                  f"position = {list(start)!r}", f"goal = {list(goal)!r}"]
    for p in followers(rows):
        ident += 1
        lines += ["", "[[agents]]", f"id = {ident}", 'role = "follower"',
                  f"position = {[float(v) for v in p]!r}"]
    return "\n".join(lines) + "\n"


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, help="directory for design.toml, sweep.csv, sweep.png")
    p.add_argument("--rows", type=int, default=3, help="rows of followers in the triangle")
    p.add_argument("--sweep", default="4:40:4", help="travel times LO:HI:STEP in seconds")
    args = p.parse_args()
    os.makedirs(args.out, exist_ok=True)

    lo, hi, step = (float(v) for v in args.sweep.split(":"))
    times = np.arange(lo, hi + step / 2, step)

    # 1. Design: the TOML text, validated like a file (cdm.parse), and saved.
    text = design(args.rows, t_total_s=float(times[-1]))
    scenario = cdm.parse(text, origin="design.toml")
    path = os.path.join(args.out, "design.toml")
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)
    scenario = cdm.load(path)
    print(scenario)

    # 2. Certify (the CLI's `plan`): lambda_1, D_B, D_S, delta, T_threshold.
    cert = cdm.plan(scenario)
    print(f"verdict {cert.verdict} lambda_1 {cert.lambda_1!r} D_B {cert.d_b_m!r} "
          f"D_S {cert.d_s_m!r} delta {cert.delta_m!r}")
    for reason in cert.reasons:
        print(f"reason {reason}")

    # 3. Sweep the travel time (the CLI's `plan --sweep`): E_max against T.
    deviations = cdm.sweep(scenario, times)
    for t, e in zip(times, deviations):
        print(f"T {float(t)!r} deviation {float(e)!r}")
    print(f"T_threshold {cert.t_threshold_s!r}")
    with open(os.path.join(args.out, "sweep.csv"), "w", encoding="utf-8") as f:
        f.write("t_total_s,max_follower_deviation_m\n")
        for t, e in zip(times, deviations):
            f.write(f"{float(t)!r},{float(e)!r}\n")

    # 4. Fly it at its own travel time and look at the worst follower.
    flight = cdm.simulate(scenario)
    tel = flight.telemetry
    follower = tel["role"] == "follower"
    gap = np.sqrt(sum((tel[a][follower] - tel[a + "_ht"][follower]) ** 2 for a in ("x", "y", "z")))
    print(f"flight {flight.verdict} rows {len(tel['tick'])} "
          f"max_follower_deviation {flight.audit['max_follower_deviation_m']!r} "
          f"largest_follower_gap_in_telemetry {float(gap.max())!r}")

    # 5. The figure, when matplotlib is there.
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("plot skipped: matplotlib is not installed")
        return 0
    fig, ax = plt.subplots()
    ax.plot(times, deviations, marker="o", label="max follower deviation")
    ax.axhline(cert.delta_m, color="red", linestyle="--", label="delta (eq. 38)")
    if np.isfinite(cert.t_threshold_s):
        ax.axvline(cert.t_threshold_s, color="gray", linestyle=":", label="T_threshold")
    ax.set_xlabel("T_total (s)")
    ax.set_ylabel("deviation (m)")
    ax.legend()
    fig.savefig(os.path.join(args.out, "sweep.png"))
    print(f"plot {os.path.join(args.out, 'sweep.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
