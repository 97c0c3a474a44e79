"""Safe continuum deformation of quadcopter teams, from Python.

The planner of the `orchestrator` CLI as a package: `load` a scenario, `plan` it (the
pre-flight certificate), `simulate` it (telemetry as NumPy arrays, the audit as a dict) and
`export` it to Crazyswarm2 or Skybrush. Every number comes from the crates the CLI runs, so it
equals the CLI's bit for bit; a refusal raises `BadInput` (or `Fault`) with the CLI's message.

    import cdm
    cert = cdm.plan("paper40")            # a built-in, a scenario file, or cdm.load(n=12)
    print(cert.verdict, cert.delta_m, cert.t_threshold_s)
    flight = cdm.simulate("paper40")
    flight.telemetry["x"], flight.audit["max_deviation_m"]

The live shared-memory bus reader is the separate module `cdm_bus.py` beside this package (it
needs the `iceoryx2` package and a running team).
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, Iterable, Optional, Union

import numpy as np

from ._cdm import (
    Airspace,
    BadInput,
    CdmError,
    Certificate,
    Clearance,
    Fault,
    Phase,
    Scenario,
    parse,
)
from . import _cdm

__all__ = [
    "Airspace",
    "BadInput",
    "CdmError",
    "Certificate",
    "Clearance",
    "Export",
    "Fault",
    "Flight",
    "Phase",
    "Scenario",
    "deviation",
    "export",
    "load",
    "parse",
    "plan",
    "simulate",
    "sweep",
]

ScenarioLike = Union[Scenario, str, "os.PathLike[str]"]

# The dtype of each telemetry.csv column that is not a float64 (`role` is text).
_INTEGER_COLUMNS = {"tick": "<u8", "id": "<u4"}


def load(
    source: Optional[Union[str, "os.PathLike[str]"]] = None,
    *,
    n: Optional[int] = None,
    t_total_s: Optional[float] = None,
) -> Scenario:
    """Load and validate a scenario, as the CLI's `--scenario FILE`, `--builtin NAME` or `--n N`.

    `source` is a path (anything path-like, or a string naming an existing file, holding a
    separator or ending in `.toml`) or a built-in's name (`paper40`, the default); `n` generates
    a team of N members instead (4..=2000). `t_total_s` overrides the travel time
    (`--t-total`). Raises `BadInput` with the CLI's message.
    """
    if n is not None:
        if source is not None:
            raise BadInput("load: give a scenario or n, not both")
        return _cdm.load(n=n, t_total_s=t_total_s)
    if source is None:
        return _cdm.load(t_total_s=t_total_s)
    if _is_path(source):
        return _cdm.load(path=os.fspath(source), t_total_s=t_total_s)
    return _cdm.load(builtin=str(source), t_total_s=t_total_s)


def _is_path(source: Union[str, "os.PathLike[str]"]) -> bool:
    if not isinstance(source, str):
        return True
    return os.sep in source or source.endswith(".toml") or os.path.isfile(source)


def _scenario(s: ScenarioLike) -> Scenario:
    return s if isinstance(s, Scenario) else load(s)


def plan(
    scenario: ScenarioLike,
    *,
    losses: bool = False,
    suggest: bool = False,
    threads: Optional[int] = None,
) -> Certificate:
    """The pre-flight certificate of `orchestrator plan`: verdict, lambda_1, D_B, D_S, delta,
    T_threshold, a mission's phases, the airspace's margins and the reasons.

    `losses` certifies the loss of every single member as `plan --losses` (on `threads`
    threads, all cores by default), `suggest` adds the offsets that clear the airspace's
    breaches (`plan --suggest`); both then appear in `Certificate.json`, which is `plan
    --json`'s file byte for byte.
    """
    return _cdm.plan(_scenario(scenario), losses, suggest, threads)


def deviation(scenario: ScenarioLike, t_total_s: float) -> float:
    """The max follower deviation (metres, 2-norm) of the plan flown in `t_total_s` seconds:
    one point of `plan --sweep` (infinite when the flight faults)."""
    return _cdm.deviation_at(_scenario(scenario), float(t_total_s))


def sweep(scenario: ScenarioLike, times_s: Iterable[float]) -> np.ndarray:
    """`deviation` at each travel time: the curve `plan --sweep` draws against delta."""
    s = _scenario(scenario)
    return np.array([_cdm.deviation_at(s, float(t)) for t in times_s], dtype=np.float64)


class Flight:
    """A simulated flight: `verdict`, `telemetry` (telemetry.csv's columns as NumPy arrays),
    `audit` (audit.json as a dict) and `run_dir` (None when the run went to a temporary
    directory)."""

    verdict: str
    telemetry: Dict[str, np.ndarray]
    audit: Dict[str, Any]
    run_dir: Optional[Path]

    def __init__(
        self,
        verdict: str,
        telemetry: Dict[str, np.ndarray],
        audit: Dict[str, Any],
        run_dir: Optional[Path],
    ) -> None:
        self.verdict = verdict
        self.telemetry = telemetry
        self.audit = audit
        self.run_dir = run_dir

    def table(self) -> Any:
        """The telemetry as a `pyarrow.Table` (needs the `pyarrow` package)."""
        import pyarrow as pa

        return pa.table(self.telemetry)

    def __repr__(self) -> str:
        rows = len(next(iter(self.telemetry.values()), ()))
        return f"Flight({self.verdict}: {rows} telemetry rows, run_dir={self.run_dir})"


def read_run(run_dir: Union[str, "os.PathLike[str]"]) -> Flight:
    """A finished run directory (`simulate`, `launch`, the CLI's or this package's) as a
    Flight: its telemetry (telemetry.csv or telemetry.parquet) and audit.json."""
    path = Path(run_dir)
    columns = _cdm.read_telemetry(os.fspath(path))
    telemetry: Dict[str, np.ndarray] = {}
    for name, values in columns.items():
        if name == "role":
            telemetry[name] = np.array(values, dtype=str)
        else:
            telemetry[name] = np.frombuffer(values, dtype=_INTEGER_COLUMNS.get(name, "<f8"))
    try:
        with open(path / "audit.json", encoding="utf-8") as f:
            audit = json.load(f)
    except (OSError, ValueError) as e:
        raise BadInput(f"{path / 'audit.json'}: {e}") from e
    return Flight(str(audit.get("verdict")), telemetry, audit, path)


def simulate(
    scenario: ScenarioLike,
    out: Optional[Union[str, "os.PathLike[str]"]] = None,
    *,
    force: bool = False,
    every: Optional[int] = None,
    max_ticks: Optional[int] = None,
    stop_on_violation: bool = False,
) -> Flight:
    """Fly the team with the deterministic in-process engine, as `orchestrator simulate`.

    The run directory is `out` (refused when it exists and is not empty, unless `force`), or a
    temporary one removed once read. `every` keeps every K-th tick in telemetry (default: the
    CLI's, about 40 rows a tick), `max_ticks` flies ticks 0..=K, `stop_on_violation` ends the
    run at its first violation. The figures and replay.html of the CLI are not drawn.
    """
    s = _scenario(scenario)
    if out is not None:
        verdict = _cdm.simulate(s, os.fspath(out), force, every, max_ticks, stop_on_violation)
        flight = read_run(out)
        flight.verdict = verdict
        return flight
    with tempfile.TemporaryDirectory(prefix="cdm-flight-") as tmp:
        run = Path(tmp) / "run"
        verdict = _cdm.simulate(s, os.fspath(run), False, every, max_ticks, stop_on_violation)
        flight = read_run(run)
    flight.verdict = verdict
    flight.run_dir = None
    return flight


@dataclass(frozen=True)
class Export:
    """What `export` wrote: the target, where, the certificate's verdict at the target scale,
    whether the trajectory files were written, and certificate.json as a dict."""

    target: str
    out: Path
    verdict: str
    written: bool
    certificate: Dict[str, Any]


def export(
    scenario: ScenarioLike,
    target: str,
    out: Union[str, "os.PathLike[str]"],
    *,
    scale: float = 1.0,
    origin: Optional[str] = None,
    eps: float = 0.1,
    force: bool = False,
) -> Export:
    """The plan for a real fleet, as `orchestrator export crazyswarm2|skybrush`: mapped
    p -> scale p + origin (`"X,Y,Z"` metres) for vehicles of radius `eps`, certified again at
    that scale. `crazyswarm2` writes a directory, `skybrush` a .skyc file (with
    <stem>.certificate.json beside it). An UNSAFE certificate writes only the certificate
    unless `force` (`Export.written`). A scenario from `parse` is exported from its TOML.
    Nothing is printed: the verdict and the certificate are in the returned `Export`.
    """
    s = _scenario(scenario)
    out = Path(out)
    if not s.has_source:
        with tempfile.TemporaryDirectory(prefix="cdm-export-") as tmp:
            path = Path(tmp) / f"{s.name}.toml"
            path.write_text(s.to_toml(), encoding="utf-8")
            return export(load(path), target, out, scale=scale, origin=origin, eps=eps, force=force)
    verdict, written = _cdm.export(s, target, os.fspath(out), scale, origin, eps, force)
    if target == "crazyswarm2":
        record = out / "certificate.json"
    else:
        record = out.parent / f"{out.stem}.certificate.json"
    with open(record, encoding="utf-8") as f:
        certificate = json.load(f)
    return Export(target, out, verdict, written, certificate)
