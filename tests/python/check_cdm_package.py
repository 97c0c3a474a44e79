"""Check the `cdm` Python package against the orchestrator CLI.

Usage:
  check_cdm_package.py same SCENARIO CLI_RUN_DIR CLI_PLAN.json
      `cdm.plan(SCENARIO)` and `cdm.simulate(SCENARIO)` (SCENARIO: a built-in name or a file)
      against `orchestrator plan --json` and `orchestrator simulate --out CLI_RUN_DIR`: the
      certificate's JSON byte for byte and its typed fields equal to that JSON's values, the
      audit dict equal to audit.json, and every telemetry column equal, value for value and in
      its type, to telemetry.csv read with Python's csv module (shortest round-trip floats:
      float(text) is the very same double). Prints one line; exits 1 naming the first
      difference.
  check_cdm_package.py refuse CALL ARG...
      Runs one call that must fail and prints `<exception class>: <message>`:
      `load PATH_OR_NAME`, `plan PATH_OR_NAME`, `simulate PATH_OR_NAME OUT`, `generated N`.
  check_cdm_package.py export SCENARIO TARGET OUT SCALE
      `cdm.export(SCENARIO, TARGET, OUT, scale=SCALE)`; prints `export <verdict> <written>` last
      (the files are compared with the CLI's by the Rust test).
"""

import json
import math
import sys

import numpy as np

import cdm
# telemetry.csv read with Python's csv module, ints and floats parsed (the Parquet check's reader).
from parquet_equals_csv import read_csv

# telemetry.csv's column types as the package hands them out.
DTYPES = {"tick": np.uint64, "id": np.uint32, "role": np.str_}


def fail(what):
    print(f"MISMATCH {what}", file=sys.stderr)
    sys.exit(1)


def same_number(a, b):
    """Equal doubles; JSON's null stands for a non-finite number (serde_json writes null)."""
    if b is None:
        return a is None or not math.isfinite(a)
    return a == b and type(b) in (int, float)


def check_certificate(cert, text):
    if cert.json != text:
        fail("the certificate's JSON differs from `plan --json`'s file")
    j = json.loads(text)
    fields = {
        "verdict": "verdict",
        "reasons": "reasons",
        "scenario": "scenario",
        "agents": "agents",
        "lambda_1": "lambda1_min",
        "t_lambda_1_s": "t_lambda1_min_s",
        "lambda_cd_min": "lambda_cd_min",
        "d_b_m": "d_b_m",
        "d_s_m": "d_s_m",
        "delta_max_m": "delta_max_m",
        "delta_m": "delta_m",
        "eps_m": "eps_m",
        "t_threshold_s": "t_threshold_s",
        "t_total_s": "t_total_s",
        "max_follower_deviation_m": "max_follower_deviation_m",
        "gains_stability_margin": "gains_stability_margin",
        "max_link_delay_ms": "max_link_delay_ms",
        "max_link_delay_at_least": "max_link_delay_at_least",
        "notes": "notes",
    }
    for attr, key in fields.items():
        a, b = getattr(cert, attr), j[key]
        if isinstance(b, (list, str, bool)) and a != b:
            fail(f"certificate.{attr} = {a!r}, the CLI's {key} = {b!r}")
        if not isinstance(b, (list, str, bool)) and not same_number(a, b):
            fail(f"certificate.{attr} = {a!r}, the CLI's {key} = {b!r}")
    phases = j.get("segments") or []
    if len(cert.phases) != len(phases):
        fail(f"{len(cert.phases)} phases, the CLI's {len(phases)}")
    for p, q in zip(cert.phases, phases):
        for attr, key in [("name", "name"), ("t_start_s", "t_start_s"), ("t_end_s", "t_end_s"),
                          ("lambda_1", "lambda1_min"), ("d_b_m", "d_b_m"), ("d_s_m", "d_s_m"),
                          ("delta_m", "delta_m"), ("t_threshold_s", "t_threshold_s"),
                          ("max_follower_deviation_m", "max_follower_deviation_m"),
                          ("verdict", "verdict"), ("reasons", "reasons")]:
            a, b = getattr(p, attr), q[key]
            if (a != b) if isinstance(b, (list, str)) else not same_number(a, b):
                fail(f"phase {p.name}: {attr} = {a!r}, the CLI's {b!r}")
    airspace = j.get("airspace")
    if (cert.airspace is None) != (airspace is None):
        fail("airspace present on one side only")
    if airspace is not None:
        if not same_number(cert.airspace.radius_m, airspace["radius_m"]):
            fail(f"airspace radius {cert.airspace.radius_m!r}, the CLI's {airspace['radius_m']!r}")
        got = [(c.kind, c.name, c.margin_m, c.agent, c.t_s, c.phase)
               for c in cert.airspace.clearances]
        want = [(c["kind"], c["name"], c["margin_m"], c["agent"], c["t_s"], c["phase"])
                for c in airspace["clearances"]]
        if got != want:
            fail(f"airspace clearances {got}, the CLI's {want}")
    return len(cert.phases)


def check_telemetry(telemetry, path):
    header, cols = read_csv(path)
    if list(telemetry) != header:
        fail(f"columns {list(telemetry)}, telemetry.csv's {header}")
    for name in header:
        got = telemetry[name]
        want_type = DTYPES.get(name, np.float64)
        if got.dtype.type is not want_type:
            fail(f"column {name}: dtype {got.dtype}, expected {want_type.__name__}")
        if name == "role":
            same = got.tolist() == cols[name]
        else:
            want = np.array(cols[name], dtype=want_type)
            # Bit for bit: the very same doubles (and -0.0 is not 0.0).
            same = got.shape == want.shape and got.tobytes() == want.tobytes()
        if not same:
            fail(f"column {name} differs from telemetry.csv")
    return len(cols["tick"])


def same(source, cli_run, cli_plan):
    with open(cli_plan, encoding="utf-8") as f:
        text = f.read()
    phases = check_certificate(cdm.plan(source), text)
    flight = cdm.simulate(source)
    with open(f"{cli_run}/audit.json", encoding="utf-8") as f:
        audit = json.load(f)
    if flight.audit != audit:
        diff = [k for k in audit if flight.audit.get(k) != audit[k]]
        fail(f"audit differs from the CLI's audit.json in {diff}")
    if flight.verdict != audit["verdict"]:
        fail(f"verdict {flight.verdict}, the CLI's {audit['verdict']}")
    rows = check_telemetry(flight.telemetry, f"{cli_run}/telemetry.csv")
    print(f"same {source}: verdict {flight.verdict}, certificate {json.loads(text)['verdict']} "
          f"with {phases} phase(s), {rows} telemetry rows")


def refuse(call, args):
    try:
        if call == "load":
            cdm.load(args[0])
        elif call == "plan":
            cdm.plan(args[0])
        elif call == "simulate":
            cdm.simulate(args[0], args[1])
        elif call == "generated":
            cdm.load(n=int(args[0]))
        else:
            fail(f"unknown call {call}")
    except cdm.CdmError as e:
        print(f"{type(e).__name__}: {e}")
        return
    fail(f"{call} {args} did not raise")


def export(source, target, out, scale):
    e = cdm.export(source, target, out, scale=float(scale))
    if e.certificate["certificate"]["verdict"] != e.verdict:
        fail(f"verdict {e.verdict}, certificate.json's {e.certificate['certificate']['verdict']}")
    print(f"export {e.verdict} {e.written}")


def main():
    if sys.argv[1] == "same":
        same(*sys.argv[2:5])
    elif sys.argv[1] == "export":
        export(*sys.argv[2:6])
    else:
        refuse(sys.argv[2], sys.argv[3:])


if __name__ == "__main__":
    main()
