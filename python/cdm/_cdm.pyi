"""Type stubs of the native module `cdm._cdm` (crate cdm-python, python/src). Use the functions
of `cdm` itself: they accept paths and names where these take a `Scenario`."""

from typing import Dict, List, Optional, Tuple, Union

class CdmError(Exception):
    """Any failure of the cdm package; the message is the orchestrator CLI's."""

class BadInput(CdmError):
    """Refused input (the CLI's exit 2): a scenario file, field, name or option, named in the
    message."""

class Fault(CdmError):
    """A run that could not complete (the CLI's exit 3): a control fault, a file that cannot
    be written."""

class Scenario:
    """A validated scenario (`cdm.load`, `cdm.parse`)."""

    @property
    def name(self) -> str: ...
    @property
    def origin(self) -> str:
        """Where it was read from (a path, `built-in paper40`, ...)."""
    @property
    def ids(self) -> List[int]:
        """The members' ids in file order."""
    @property
    def agents(self) -> int:
        """Number of members."""
    @property
    def t_total_s(self) -> float:
        """The travel time (seconds)."""
    @property
    def dt_s(self) -> float:
        """The tick (seconds): 1 / comm_hz."""
    @property
    def last_tick(self) -> int: ...
    @property
    def is_mission(self) -> bool:
        """Whether the plan is a mission (take-off, segments, landing)."""
    @property
    def notes(self) -> List[str]:
        """The notes validation made (defaults it filled in)."""
    @property
    def has_source(self) -> bool:
        """Loaded from a file, a built-in or `n` (not parsed from text)."""
    def to_toml(self) -> str:
        """The scenario as TOML (`orchestrator scenario export`)."""
    def to_json(self) -> str: ...

class Phase:
    """One phase of a mission, certified (`takeoff`, `segment N`, `landing`)."""

    name: str
    t_start_s: float
    t_end_s: float
    lambda_1: float
    t_lambda_1_s: float
    d_b_m: float
    d_s_m: float
    delta_m: float
    t_threshold_s: float
    max_follower_deviation_m: float
    min_ground_separation_m: Optional[float]
    verdict: str
    reasons: List[str]

class Clearance:
    """The smallest margin to one boundary of the airspace."""

    kind: str
    """`fence` or `obstacle`."""
    name: str
    margin_m: float
    """Negative inside an obstacle or beyond the fence."""
    agent: int
    t_s: float
    phase: str

class Airspace:
    """The airspace's margins: every fence side, then every obstacle."""

    radius_m: float
    """eps + delta (eq. 38)."""
    clearances: List[Clearance]

class Certificate:
    """The pre-flight certificate (`orchestrator plan`)."""

    verdict: str
    """`SAFE` or `UNSAFE`."""
    reasons: List[str]
    scenario: str
    agents: int
    lambda_1: float
    """min lambda_1(U_D) over the plan (eq. 37)."""
    t_lambda_1_s: float
    lambda_cd_min: float
    d_b_m: float
    d_s_m: float
    delta_max_m: float
    """eq. 35."""
    delta_m: float
    """eq. 38."""
    eps_m: float
    t_threshold_s: float
    """Smallest travel time whose max follower deviation stays under delta (eq. 34)."""
    t_total_s: float
    max_follower_deviation_m: float
    gains_stability_margin: float
    """eq. 26."""
    max_link_delay_ms: Optional[float]
    max_link_delay_at_least: bool
    notes: List[str]
    phases: List[Phase]
    """A mission's phases in flight order (empty otherwise)."""
    airspace: Optional[Airspace]
    """None without a fence or obstacles."""
    json: str
    """`plan --json`'s text, byte for byte."""

def load(
    path: Optional[str] = None,
    builtin: Optional[str] = None,
    n: Optional[int] = None,
    t_total_s: Optional[float] = None,
) -> Scenario: ...
def parse(text: str, origin: str = "<text>") -> Scenario:
    """A scenario from TOML text, validated fully."""
def plan(
    scenario: Scenario,
    losses: bool = False,
    suggest_offsets: bool = False,
    threads: Optional[int] = None,
) -> Certificate: ...
def deviation_at(scenario: Scenario, t_total_s: float) -> float: ...
def simulate(
    scenario: Scenario,
    out: str,
    force: bool = False,
    every: Optional[int] = None,
    max_ticks: Optional[int] = None,
    stop_on_violation: bool = False,
) -> str: ...
def read_telemetry(run_dir: str) -> Dict[str, Union[bytes, List[str]]]: ...
def export(
    scenario: Scenario,
    target: str,
    out: str,
    scale: float = 1.0,
    origin: Optional[str] = None,
    eps: float = 0.1,
    force: bool = False,
) -> Tuple[str, bool]: ...
