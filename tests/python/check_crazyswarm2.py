"""Check an `orchestrator export crazyswarm2` directory with code nobody here wrote:
cflib's Poly4D packs every piece and TrajectoryMemory writes them (total bytes within the
Crazyflie's 4 KiB), and numpy evaluates the pieces at 1,000 instants against the plan's r_HT
from `simulate`'s telemetry: 1e-6 m in double precision, 1 mm (and the exported bound) in
single precision, evaluated the way the firmware does.

A mission's files are checked over its whole duration (certificate.json `duration_s`); with
GROUND_Z, every trajectory must start and end on the ground at that height.

usage: check_crazyswarm2.py EXPORT_DIR TELEMETRY_CSV [GROUND_Z]
"""
import json
import struct
import sys
from pathlib import Path

import numpy as np
import yaml
from cflib.crazyflie.mem.trajectory_memory import Poly4D, TrajectoryMemory

from export_common import fail, pick_instants, reference

MEMORY_BYTES = 4096
HEADER = ["duration"] + [f"{a}^{k}" for a in ("x", "y", "z", "yaw") for k in range(8)]


class Capture:
    """Stands in for cflib's radio link: keeps what TrajectoryMemory would send."""

    def __init__(self):
        self.data = None

    def write(self, mem, addr, data, flush_queue=False):
        self.data = bytes(data)


def load(path):
    with open(path) as f:
        header = f.readline().strip().split(",")
    if header != HEADER:
        fail(f"{path}: header {header}")
    rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2, dtype=np.float64)
    if rows.shape[1] != 33:
        fail(f"{path}: {rows.shape[1]} columns, want 33")
    return rows


def pack(rows):
    """Every piece through cflib: Poly4D, then TrajectoryMemory.write_data."""
    trajectory = [
        Poly4D(
            float(r[0]),
            Poly4D.Poly([float(v) for v in r[1:9]]),
            Poly4D.Poly([float(v) for v in r[9:17]]),
            Poly4D.Poly([float(v) for v in r[17:25]]),
            Poly4D.Poly([float(v) for v in r[25:33]]),
        )
        for r in rows
    ]
    link = Capture()
    memory = TrajectoryMemory(id=0, type=0, size=MEMORY_BYTES, mem_handler=link)
    memory.trajectory = trajectory
    sent = memory.write_data(lambda *a: None)
    return link.data, sent


def eval_f64(rows, t):
    starts = np.concatenate([[0.0], np.cumsum(rows[:, 0])[:-1]])
    k = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(rows) - 1)
    u = t - starts[k]
    out = np.zeros((len(t), 3))
    for axis in range(3):
        c = rows[k, 1 + 8 * axis: 9 + 8 * axis]
        acc = np.zeros(len(t))
        for m in range(7, -1, -1):
            acc = acc * u + c[:, m]
        out[:, axis] = acc
    return out


def eval_f32(packed, pieces, t):
    """The firmware's way: f32 coefficients and durations from the packed bytes, the local time
    found by subtracting f32 durations, Horner in f32."""
    f32 = np.float32
    coeffs = np.frombuffer(packed, dtype="<f4").reshape(pieces, 33)
    out = np.zeros((len(t), 3))
    for i, ti in enumerate(t):
        local = f32(ti)
        k = 0
        while k < pieces - 1 and local > coeffs[k, 32]:
            local = f32(local - coeffs[k, 32])
            k += 1
        for axis in range(3):
            acc = f32(0.0)
            for m in range(7, -1, -1):
                acc = f32(acc * local + coeffs[k, 8 * axis + m])
            out[i, axis] = acc
    return out


def on_the_ground(ident, rows, packed, t_total, ground_z, bound):
    """The first and the last point, in double and in single precision, at the ground's z."""
    ends = np.array([0.0, t_total])
    z64 = eval_f64(rows, ends)[:, 2]
    z32 = eval_f32(packed, rows.shape[0], ends)[:, 2]
    if np.abs(z64 - ground_z).max() > 1e-9 or np.abs(z32 - ground_z).max() > bound:
        fail(f"{ident}.csv: z at 0 and {t_total} s is {z64} (f32 {z32}), the ground is {ground_z}")


def main(export_dir, telemetry, ground_z=None):
    export_dir = Path(export_dir)
    cert = json.loads((export_dir / "certificate.json").read_text())
    t_total = cert.get("duration_s", cert["certificate"]["t_total_s"])
    bound = cert["f32_bound_m"]
    if not bound <= 1e-3:
        fail(f"certificate.json: f32 bound {bound}")
    ref = reference(telemetry)
    fleet = yaml.safe_load((export_dir / "crazyflies.yaml").read_text())["robots"]
    worst64 = worst32 = 0.0
    total_bytes = 0
    for ident, (t_all, r_all) in sorted(ref.items()):
        rows = load(export_dir / f"{ident}.csv")
        if abs(rows[:, 0].sum() - t_total) > 1e-9 * t_total:
            fail(f"{ident}.csv: durations sum to {rows[:, 0].sum()}, T_total {t_total}")
        if rows.shape[0] != cert["pieces_per_agent"]:
            fail(f"{ident}.csv: {rows.shape[0]} pieces, certificate says {cert['pieces_per_agent']}")
        packed, sent = pack(rows)
        if len(packed) != sent or sent != 132 * rows.shape[0] or sent > MEMORY_BYTES:
            fail(f"{ident}.csv: cflib packs {sent} bytes for {rows.shape[0]} pieces")
        if sent != cert["trajectory_bytes"]:
            fail(f"{ident}.csv: {sent} bytes, certificate says {cert['trajectory_bytes']}")
        total_bytes = max(total_bytes, sent)
        if ground_z is not None:
            on_the_ground(ident, rows, packed, t_total, float(ground_z), bound)
        idx = pick_instants(t_all, t_total)
        t, want = t_all[idx], r_all[idx]
        worst64 = max(worst64, np.abs(eval_f64(rows, t) - want).max())
        worst32 = max(worst32, np.abs(eval_f32(packed, rows.shape[0], t) - want).max())
        start = fleet[f"cf{ident}"]["initial_position"]
        if abs(start[0] - r_all[0, 0]) > 1e-9 or abs(start[1] - r_all[0, 1]) > 1e-9:
            fail(f"crazyflies.yaml cf{ident}: initial_position {start}, r_HT(0) {r_all[0]}")
    if worst64 > 1e-6:
        fail(f"double precision: {worst64} m from r_HT (limit 1e-6 m)")
    if worst32 > 1e-3 or worst32 > bound:
        fail(f"single precision: {worst32} m from r_HT (limit 1e-3 m, exported bound {bound} m)")
    print(
        f"crazyswarm2 ok: {len(ref)} quadcopters, {cert['pieces_per_agent']} pieces, "
        f"{total_bytes} of {MEMORY_BYTES} bytes (cflib), max error f64 {worst64:.3e} m, "
        f"f32 {worst32:.3e} m (bound {bound:.3e} m), {t_total} s"
        + ("" if ground_z is None else f", from and to the ground at z = {ground_z}")
    )


if __name__ == "__main__":
    main(*sys.argv[1:4])
