"""Python on a team's live bus: the wire types of `common/member/src/messages.rs` as ctypes structures,
and the iceoryx2 configuration of the runtime's processes, for the `iceoryx2` package from PyPI
(0.10, the version of the Rust side).

Each agent publishes its states on `cdm/<team>/state/<id>`, up to `STATES_PER_SAMPLE` consecutive
ticks per sample (`StateBatch`, `cdm_iox::StateBatch`); a team keeps one spare subscriber slot
on each of these services for an observer such as `examples/watch.py`. An observer never slows
the team: when it falls behind, it loses its oldest samples.
"""

import ctypes
import json
import math
import os
import re
import socket
import stat
import time

import iceoryx2 as iox2

# Where the runtime keeps iceoryx2's files and what its shared-memory names start with. Mirrors
# the one Rust function that decides both (cdm-iox, `common::transport`: root and global
# prefix); tests/tests/python_bus.rs checks the two agree. Change them here only.
ROOT_FORMAT = "/dev/shm/cdm-iceoryx2-{uid}/"
PREFIX_FORMAT = "cdm{uid}_"


def bus_paths(uid=None):
    """The iceoryx2 root directory and global prefix of the runtime for user `uid`."""
    uid = os.getuid() if uid is None else uid
    return ROOT_FORMAT.format(uid=uid), PREFIX_FORMAT.format(uid=uid)


SHM_DIR = "/dev/shm"


def restrict_global_mgmt(prefix=None):
    """Makes this user's iceoryx2 management segments owner-only, as the Rust side does
    (cdm-iox `ownership::check_global_mgmt`): iceoryx2 creates `/dev/shm/<prefix>*.global_mgmt`
    with mode 0666 even under our own prefix, and any local user could then write into it. One
    owned by another user is refused, naming it. Returns the paths it changed."""
    prefix = bus_paths()[1] if prefix is None else prefix
    changed = []
    for name in sorted(os.listdir(SHM_DIR)):
        if not (name.startswith(prefix) and name.endswith(".global_mgmt")):
            continue
        path = os.path.join(SHM_DIR, name)
        # O_PATH: examine and chmod exactly this file (no symlink), without read or write access.
        try:
            fd = os.open(path, os.O_PATH | os.O_NOFOLLOW | os.O_CLOEXEC)
        except FileNotFoundError:
            continue
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                raise PermissionError(f"{path} is not a regular file; refusing to use it")
            if st.st_uid != os.getuid():
                raise PermissionError(
                    f"{path} is owned by uid {st.st_uid}, not this user ({os.getuid()}): "
                    "another user may have planted it; refusing to use it"
                )
            if st.st_mode & 0o077:
                os.chmod(f"/proc/self/fd/{fd}", stat.S_IMODE(st.st_mode) & 0o700)
                changed.append(path)
        finally:
            os.close(fd)
    return changed


def bus_config():
    """An iceoryx2 config equal to the runtime's where it matters to open its services."""
    config = iox2.config.default()
    root, prefix = bus_paths()
    config.global_cfg.root_path = iox2.Path.new(root)
    config.global_cfg.prefix = iox2.FileName.new(prefix)
    return config


class StateMsg(ctypes.Structure):
    """One agent's full state at one tick (`common::messages::StateMsg`, 128 bytes)."""

    _fields_ = [
        ("tick", ctypes.c_uint64),
        ("scenario_hash", ctypes.c_uint64),
        ("id", ctypes.c_uint32),
        ("status", ctypes.c_uint32),
        ("fault_code", ctypes.c_uint32),
        ("fault_peer", ctypes.c_uint32),
        # x y z, vx vy vz, then attitude and rates: the layout of common/member/src/dynamics.rs.
        ("state", ctypes.c_double * 12),
    ]

    @staticmethod
    def type_name():
        """The stable name the Rust type declares (`cdm_iox::STATE_TYPE_NAME`)."""
        return "cdm::State"

    def position(self):
        return (self.state[0], self.state[1], self.state[2])


# The most states one sample carries (`cdm_iox::STATES_PER_SAMPLE`).
STATES_PER_SAMPLE = 4


class StateBatch(ctypes.Structure):
    """The payload of a state service: `states[:len]`, consecutive ticks of one agent, oldest
    first (`cdm_iox::StateBatch`, 8 + 128 * STATES_PER_SAMPLE bytes); a repeated state (a repair's
    hand-over sends the last ones again) carries the same tick and values."""

    _fields_ = [
        ("len", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),  # 1: sent again at a repair's hand-over
        ("states", StateMsg * STATES_PER_SAMPLE),
    ]

    @staticmethod
    def type_name():
        """The stable name the Rust type declares (`cdm_iox::STATE_BATCH_TYPE_NAME`)."""
        return "cdm::StateBatch"

    def messages(self):
        """The states carried, oldest first (a length past the array reads as the array)."""
        return list(self.states[: min(self.len, STATES_PER_SAMPLE)])


class ClockMsg(ctypes.Structure):
    """The orchestrator's grant (`common::messages::ClockMsg`, 144 bytes)."""

    _fields_ = [
        ("grant_tick", ctypes.c_uint64),
        ("scenario_hash", ctypes.c_uint64),
        ("command", ctypes.c_uint32),
        ("reason", ctypes.c_uint32),
        ("loss_tick", ctypes.c_uint64),
        ("loss_seq", ctypes.c_uint32),
        ("loss_id", ctypes.c_uint32),
        ("loss_linked", ctypes.c_uint32),
        ("reserved", ctypes.c_uint32),
        ("steer_tick", ctypes.c_uint64),
        ("steer_seq", ctypes.c_uint32),
        ("steer_command", ctypes.c_uint32),
        ("steer_goals", ctypes.c_double * 9),
        ("steer_travel_s", ctypes.c_double),
    ]

    @staticmethod
    def type_name():
        """The stable name the Rust type declares (`cdm_iox::CLOCK_TYPE_NAME`)."""
        return "cdm::Clock"


STATUS_OK = 0
# A real-time member's pacing report, not a state (`common::messages::STATUS_PACING`).
STATUS_PACING = 2
# `ClockMsg.command` of a real-time team: `grant_tick` is the start instant (CLOCK_REALTIME ns),
# `reason` the phase seed (`common::messages::COMMAND_REALTIME`).
COMMAND_REALTIME = 2


def state_service(team, agent_id):
    """`cdm/<team>/state/<id>`, as `common::transport::TeamName::state_service` names it."""
    return f"cdm/{team}/state/{agent_id}"


def team_ids(team, config):
    """The ids of the team's agents, from the state services iceoryx2 lists (sorted); empty
    until the orchestrator has created all of them (`cdm/<team>/wake/orch` comes last)."""
    pattern = re.compile(r"^cdm/" + re.escape(team) + r"/state/(\d+)$")
    ids = []
    complete = False
    for details in iox2.Service.list(config, iox2.ServiceType.Ipc):
        name = details.name().to_string()
        complete = complete or name == f"cdm/{team}/wake/orch"
        m = pattern.match(name)
        if m:
            ids.append(int(m.group(1)))
    return sorted(ids) if complete else []


class TeamReader:
    """Subscribes to every state service of a running team and assembles complete ticks."""

    def __init__(self, team, node_name="cdm-python"):
        self.config = bus_config()
        self.node = (
            iox2.NodeBuilder.new()
            .name(iox2.NodeName.new(node_name))
            .config(self.config)
            .create(iox2.ServiceType.Ipc)
        )
        # Creating the node made the management segment, world-writable: ours alone now.
        restrict_global_mgmt()
        self.ids = team_ids(team, self.config)
        if not self.ids:
            raise LookupError(f"team {team}: no state service (is it running, as this user?)")
        self.subscribers = {}
        for agent_id in self.ids:
            service = (
                self.node.service_builder(iox2.ServiceName.new(state_service(team, agent_id)))
                .publish_subscribe(StateBatch)
                .open()
            )
            self.subscribers[agent_id] = service.subscriber_builder().create()
        # tick -> {id: StateMsg}
        self.pending = {}
        # The newest tick returned: older samples (a buffer replayed after a publisher left, a
        # laggard) are ignored, so ticks come out strictly increasing.
        self.done_tick = -1

    def poll(self):
        """Takes every sample that arrived; returns the ticks now complete, oldest first, as
        (tick, {id: StateMsg}), each tick once and strictly increasing. A tick some agent's
        sample was lost for (the observer fell behind) is dropped once a later tick completes."""
        for agent_id, sub in self.subscribers.items():
            while True:
                sample = sub.receive()
                if sample is None:
                    break
                batch = StateBatch.from_buffer_copy(sample.payload().contents)
                sample.delete()
                for msg in batch.messages():
                    if msg.status == STATUS_OK and msg.tick > self.done_tick:
                        self.pending.setdefault(msg.tick, {})[agent_id] = msg
        done = [t for t, states in self.pending.items() if len(states) == len(self.ids)]
        out = []
        for t in sorted(done):
            out.append((t, self.pending.pop(t)))
        if done:
            self.done_tick = max(done)
            for t in [t for t in self.pending if t < self.done_tick]:
                del self.pending[t]
        return out

    def wait(self, seconds):
        """Sleeps up to `seconds` (the node's wait also notices signals)."""
        self.node.wait(iox2.Duration.from_secs_f64(seconds))


def min_separation(states):
    """The smallest distance between two agents (the audit's D_B(t), Fig. 11) and the pair."""
    pts = sorted((m.position(), i) for i, m in states.items())
    best = (float("inf"), None, None)
    for k, (p, i) in enumerate(pts):
        for q, j in pts[k + 1 :]:
            if q[0] - p[0] > best[0]:
                break
            d = math.sqrt((p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2 + (p[2] - q[2]) ** 2)
            if d < best[0]:
                best = (d, min(i, j), max(i, j))
    return best


# ---------------------------------------------------------------------------------------------
# Steering a running team: the command channel of `orchestrator command TEAM ...`
# (common/launch/src/channel.rs): a Unix socket `<team>.command` in the bus root, owner-only;
# one JSON line asked and one answered per connection. tests/tests/steering_live.rs checks this
# client against a live team.

# The answers (`channel::Answered`) and the CLI exit code each stands for.
ANSWER_EXIT = {"accepted": 0, "unsafe": 1, "bad_input": 2, "unavailable": 3}

TEAM_NAME = re.compile(r"^[A-Za-z0-9_-]{1,48}$")


class NoTeam(Exception):
    """Nothing takes commands under that team name here (exit 3 of `orchestrator command`)."""


class NoAnswer(Exception):
    """The team did not answer in time; the command may still be decided (see its
    commands.json). Exit 3 of `orchestrator command`."""


def command_socket(team, uid=None):
    """The path of team `team`'s command channel (`channel::socket_path`)."""
    return os.path.join(bus_paths(uid)[0], f"{team}.command")


def command(team, what, goals=None, travel_s=None, within_s=10.0):
    """Sends one command to a running team, as `orchestrator command TEAM WHAT ...` does, and
    returns its answer: a dict with `answer` (a key of ANSWER_EXIT), `switch_tick` and
    `t_switch_s` (when it takes effect; absent for bad input), `text` (the certificate's summary,
    or why not) and `decided_ms`. `what` is "hold", "resume", "land" or "goto"; `goals` (goto
    only) the three primary leaders' new positions as [x, y, z], ascending id order; `travel_s`
    (goto only) the travel time. Raises ValueError for bad input before asking the team, NoTeam
    when nothing listens, NoAnswer after `within_s` seconds without an answer."""
    if not TEAM_NAME.match(team or ""):
        raise ValueError(f"team name {team!r}: 1 to 48 of A-Z, a-z, 0-9, '_' and '-'")
    if what not in ("hold", "resume", "land", "goto"):
        raise ValueError(f"command {what!r}: one of hold, resume, land, goto")
    if not (isinstance(within_s, (int, float)) and math.isfinite(within_s) and 0 < within_s <= 3600):
        raise ValueError(f"within_s must be in (0, 3600] seconds, got {within_s!r}")
    request = {"command": what}
    if what == "goto":
        if goals is None or len(goals) != 3:
            raise ValueError("goto takes the goals of the 3 primary leaders")
        request["goals"] = []
        for k, g in enumerate(goals):
            if len(g) != 3 or not all(math.isfinite(float(c)) for c in g):
                raise ValueError(f"goal {k + 1}: three finite numbers [x, y, z], got {g!r}")
            request["goals"].append([float(c) for c in g])
        if travel_s is not None:
            if not (math.isfinite(float(travel_s)) and float(travel_s) > 0):
                raise ValueError(f"travel_s must be a positive number of seconds, got {travel_s!r}")
            request["travel_s"] = float(travel_s)
    elif goals is not None or travel_s is not None:
        raise ValueError(f"goals and travel_s: only goto takes them, not {what}")

    path = command_socket(team)
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        try:
            s.connect(path)
        except (FileNotFoundError, ConnectionRefusedError) as e:
            raise NoTeam(f"no team {team} takes commands here ({path}: {e})") from None
        until = time.monotonic() + within_s
        s.settimeout(within_s)
        s.sendall((json.dumps(request) + "\n").encode())
        line = b""
        try:
            while not line.endswith(b"\n"):
                # One deadline for the whole answer, however it arrives.
                s.settimeout(max(until - time.monotonic(), 1e-3))
                chunk = s.recv(65536)
                if not chunk:
                    break
                line += chunk
        except socket.timeout:
            raise NoAnswer(f"team {team} did not answer within {within_s} s") from None
    finally:
        s.close()
    if not line:
        raise NoAnswer(f"team {team} closed the channel without an answer")
    answer = json.loads(line)
    if answer.get("answer") not in ANSWER_EXIT:
        raise ValueError(f"team {team}: an answer that is not one: {line!r}")
    return answer
