"""Shared by the export checks: the plan's r_HT from `orchestrator simulate`'s own telemetry."""
import csv
import sys

import numpy as np

INSTANTS = 1000


def fail(message):
    print(f"FAIL: {message}", file=sys.stderr)
    sys.exit(1)


def reference(telemetry_path):
    """{id: (t[], r_HT[] as n x 3)} from telemetry.csv (columns t, id, x_ht, y_ht, z_ht)."""
    rows = {}
    with open(telemetry_path, newline="") as f:
        for rec in csv.DictReader(f):
            rows.setdefault(int(rec["id"]), []).append(
                (float(rec["t"]), float(rec["x_ht"]), float(rec["y_ht"]), float(rec["z_ht"]))
            )
    out = {}
    for ident, values in rows.items():
        a = np.array(values, dtype=np.float64)
        out[ident] = (a[:, 0], a[:, 1:4])
    return out


def pick_instants(t, t_total):
    """INSTANTS sample indices spread over [0, T_total] (telemetry written every K ticks)."""
    inside = np.flatnonzero(t <= t_total + 1e-9)
    if len(inside) < INSTANTS:
        fail(f"telemetry has {len(inside)} instants in [0, {t_total}] s, need {INSTANTS}")
    return inside[np.linspace(0, len(inside) - 1, INSTANTS).round().astype(int)]
