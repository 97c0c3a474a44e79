#!/usr/bin/env python3
"""A stand-in MAVLink vehicle for the tests of the member's vehicle link.

pymavlink (pinned in python/requirements-test.txt) does all the encoding and decoding, so the
Rust side is checked against an implementation nobody here wrote. The vehicle is a point mass
tracking the last SET_POSITION_TARGET_LOCAL_NED it received (position, velocity and acceleration
feed-forward), stepped at --rate-hz. From its own UDP socket to the member's port it sends
HEARTBEAT at --heartbeat-hz (1 Hz), LOCAL_POSITION_NED at --position-hz and ATTITUDE at
--attitude-hz (both --rate-hz unless given). It answers
DO_SET_MODE / COMPONENT_ARM_DISARM like a strict PX4, counts what it received and the frames that
failed their checksum, stamps every command and its own readiness (its first HEARTBEAT and
position) on the wall clock, can go silent (--silent-after), report a failsafe
(--failsafe-after), drain its battery (--battery-drain), be taken over by a pilot
(--take-over-after) or disarmed (--disarm-after), and prints one JSON summary on stdout at exit.

Every such time counts from an event of the flight, never from this process's start (on a
loaded machine the team may start seconds after its vehicles, and a failure due before the
start would race the team's own start): --take-over-after and --disarm-after from when the
vehicle was first armed in OFFBOARD/GUIDED; --silent-after, --failsafe-after and
--battery-drain from the flight's start, the first setpoint that is not the member's initial
hold (the first setpoint received, repeated while the team gets ready).

What it reproduces of PX4 (v1.14+ defaults):
- HEARTBEAT once a second (PX4 and ArduPilot send it at 1 Hz whatever the link), with
  MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, the armed flag, and the main mode in bits 16..24 of
  custom_mode (px4_custom_mode.h).
- Streams that are not metronomes: every packet leaves up to --jitter of its period late, one in
  about 1/--late-prob is held back a further --late-periods periods (with the content it had
  when due: a stale packet), and one in about 1/--dup-prob is sent twice (the same datagram, same
  sequence number). Seeded by --seed (default: the system id), so a run is reproducible.
  --exact turns all three off: every stream at exactly its rate.
- OFFBOARD is accepted only while setpoints stream, arming only in OFFBOARD (or GUIDED with
  --autopilot ardupilot), and the vehicle falls back to POSCTL when setpoints stop for PX4's
  COM_OF_LOSS_T (1 s by default; COM_OBL_RC_ACT's default with an RC link is Position mode).
  Every command gets a COMMAND_ACK.
- A pilot taking over (--take-over-after S: S seconds after the vehicle was first armed in
  OFFBOARD/GUIDED): PX4's COM_RC_OVERRIDE switches "from offboard mode (or any mode) to Position
  mode if the RC sticks are moved" (PX4 user guide, Offboard Control), so the HEARTBEAT's main
  mode becomes POSCTL (ArduCopter: the pilot's mode switch to LOITER, mode 5). From then on the
  vehicle ignores every setpoint (PX4 flies offboard setpoints only in OFFBOARD, ArduCopter
  position targets only in GUIDED) and, sticks centred, brakes and holds where it is.
- Disarmed in flight (--disarm-after S, counted the same way): the armed flag leaves the
  HEARTBEAT, the motors stop and the point mass falls to its frame's ground (NED z = 0), where
  it rests; setpoints are ignored.

Take-off, landing and the ground, with either --autopilot (the ground is its frame's NED z = 0;
a vehicle started above it is in the air, as the older tests' vehicles are):
- EXTENDED_SYS_STATE at --ext-state-hz (1 Hz) with landed_state (MAVLink common: ON_GROUND,
  IN_AIR, TAKEOFF, LANDING), as PX4 and ArduCopter (since ArduPilot PR 8265) send it: ON_GROUND
  within 5 cm of the ground and slower than 0.1 m/s.
- PX4 climbs from the ground under OFFBOARD setpoints (PX4's ROS 2 offboard example: stream,
  switch to Offboard, arm, and it ascends to the setpoint): nothing else is needed.
- MAV_CMD_NAV_LAND (PX4 user guide, "Land Mode": the command switches to Land mode, which lands
  where it was engaged at MPC_LAND_SPEED, 0.7 m/s by default; ArduCopter's LAND mode, 9, at
  LAND_SPEED, 0.5 m/s): accepted armed, refused (FAILED) disarmed.
- Disarmed by itself after landing, as both do by default: PX4 COM_DISARM_LAND after 2 s on the
  ground (its docs: "Time-out for auto disarm after landing"; any mode, once it has taken off
  since arming), ArduCopter's LAND mode at touchdown.
- A disarm (COMPONENT_ARM_DISARM param1 = 0) in the air is refused (FAILED) unless forced with
  param2 = 21196 (ArduPilot dev guide, "Arming and Disarming": "disarm the vehicle (may fail if
  not landed)", 21196 "force disarm the vehicle even if flying"; PX4 likewise); on the ground it
  is accepted.

With --autopilot ardupilot it is an ArduCopter (4.x) instead, in what the member relies on:
- GUIDED (mode 4) in HEARTBEAT.custom_mode; arming only in GUIDED.
- Armed on the ground in GUIDED it stays there whatever position target it is sent
  (mode_guided.cpp runs its ground handling until a take-off sets auto_armed); those targets
  are counted (setpoints_ignored_on_ground).
- MAV_CMD_NAV_TAKEOFF (ArduCopter takeoff.cpp, Mode::do_user_takeoff; ArduPilot dev guide,
  "Copter Commands in Guided Mode"; param7 the altitude above home, metres) gets a COMMAND_ACK:
  ACCEPTED only armed, in GUIDED, landed and to an altitude above the current one ("can't
  takeoff downwards"), otherwise FAILED. The vehicle then climbs vertically above where it armed
  at WPNAV_SPEED_UP's default, 2.5 m/s; the take-off is complete at the altitude, and position
  targets are flown from then on. During the climb its targets are counted, not flown: on a real
  ArduCopter a target during the take-off may replace it, and the member sends only targets at
  the take-off altitude meanwhile, so either way the vehicle climbs to it.
- --refuse-takeoff answers every NAV_TAKEOFF with FAILED; --stall-climb stops the climb halfway
  (a take-off that never completes).

Outdoors, with --home LAT,LON,ALT (the geographic position of its local NED origin, as PX4 sets
its local position's reference where the estimator first has a GPS fix):
- GLOBAL_POSITION_INT at the position rate besides LOCAL_POSITION_NED, as PX4 and ArduPilot
  stream both (MAVLink common: lat and lon in 1e-7 degree, alt in mm above mean sea level,
  relative_alt in mm above home, vx, vy, vz in cm/s north, east, down). The local position is
  turned into latitude and longitude by PX4's map projection (px4_geo.py: PX4's
  MapProjection::reproject; altitude = home altitude - local down).
- SET_POSITION_TARGET_GLOBAL_INT flown like the local target, as PX4's offboard guide (Offboard
  Mode, "SET_POSITION_TARGET_GLOBAL_INT": position, velocity, or position with velocity
  feed-forward; coordinate_frame MAV_FRAME_GLOBAL) and ArduPilot's guided-mode guide ("Copter
  Commands in Guided Mode": MAV_FRAME_GLOBAL(_INT) altitude AMSL, MAV_FRAME_GLOBAL_RELATIVE_ALT
  (_INT) above home) describe it: the target's latitude and longitude projected into the local
  frame with PX4's MapProjection::project about home, its altitude as local down = home altitude
  - alt (relative frames: - alt); acceleration feed-forward only when the type_mask uses it.
  A global target without --home (no GPS) is refused: counted, not flown.

Its geofence, as PX4 keeps one (PX4 user guide, "GeoFence": polygons and circles, inclusion or
exclusion, uploaded as a fence plan) through the mission protocol's fence side (mavlink.io,
"Mission Protocol", mission_type MAV_MISSION_TYPE_FENCE):
- Upload: MISSION_COUNT, then it asks for each item in turn with MISSION_REQUEST_INT and closes
  with MISSION_ACK: MAV_MISSION_ACCEPTED once every item arrived and the polygons are whole
  (every vertex of a polygon carries its vertex count as param1, as the geofence items define),
  MAV_MISSION_INVALID otherwise, and MAV_MISSION_DENIED to every upload with --refuse-fence. A
  new fence replaces the old one only once accepted.
- Download: MISSION_REQUEST_LIST answered with MISSION_COUNT, each MISSION_REQUEST_INT with that
  MISSION_ITEM_INT; the ground side's MISSION_ACK ends it.
The fence is kept and reported (summary `fence`), not enforced in flight.

What it does not reproduce:
- PX4's own stream rates on an onboard link (LOCAL_POSITION_NED 30 Hz, ATTITUDE 100 Hz in
  mavlink_main.cpp's onboard mode): the defaults here are 50 Hz for both; pass --position-hz 30
  --attitude-hz 100 for PX4's.
- Reordering (a late packet here never overtakes a newer one by more than its own delay), loss,
  BATTERY_STATUS (SYS_STATUS is sent, at PX4's onboard 5 Hz, with a battery that drains at
  --battery-drain and a 4S voltage; PX4's own low-battery failsafe is not modelled, only
  --failsafe-after's MAV_STATE_CRITICAL), preflight checks, RC, failsafes (data link loss,
  COM_DL_LOSS_T), PX4's COM_DISARM_PRFLT (it disarms an armed vehicle that has not taken off
  within 10 s), ArduCopter's DISARM_DELAY outside LAND, the land detectors' own delays, PX4's
  take-off mode (NAV_TAKEOFF to --autopilot px4 is answered UNSUPPORTED), TIMESYNC, PX4's list of messages it takes unsigned while signing (RADIO_STATUS
  and the like; here nothing unsigned is taken), and any dynamics beyond a point mass.

With --signing-key it signs as PX4 does with a key on its SD card (pymavlink's MAVLink 2
signing: every frame signed, unsigned and wrongly signed frames refused and counted); a
duplicated packet is then the same signed frame again, a replay.

Every loop is bounded: the vehicle exits after --max-s seconds, or --idle-exit-s seconds after
the last setpoint.

How to run (with the Rust example listening on 127.0.0.1:14540):
    .venv/bin/python tests/python/mavlink_vehicle.py --port 14540 --start-ned 0,0,-2
"""

import argparse
import json
import heapq
import math
import os
import random
import sys
import time

from px4_geo import MapProjection

# MAVLink 2 and the common dialect (what PX4 speaks) must be chosen before pymavlink loads one.
os.environ["MAVLINK20"] = "1"
os.environ["MAVLINK_DIALECT"] = "common"
from pymavlink import mavutil  # noqa: E402

mavutil.set_dialect("common")
mavlink = mavutil.mavlink

PX4_MAIN_MODE_OFFBOARD = 6
ARDUCOPTER_GUIDED = 4
# The vehicle's tracking law: a critically damped second-order loop (omega = 3 rad/s).
KP = 9.0
KD = 6.0
GRAVITY = 9.81
# PX4 drops out of OFFBOARD when setpoints stop for this long (COM_OF_LOSS_T, default 1 s).
OFFBOARD_LOSS_S = 1.0
PX4_MAIN_MODE_POSCTL = 3
ARDUCOPTER_LOITER = 5
# ArduCopter's default climb speed of a take-off (WPNAV_SPEED_UP, 250 cm/s).
ARDUCOPTER_TAKEOFF_SPEED = 2.5
# On the ground (landed_state ON_GROUND): this close to NED z = 0 and this slow.
GROUND_TOLERANCE_M = 0.05
GROUND_SPEED_MPS = 0.1
# Land mode: PX4 AUTO (main mode 4) LAND (sub mode 6); ArduCopter LAND (9); their descent speeds
# (MPC_LAND_SPEED 0.7 m/s, LAND_SPEED 50 cm/s by default).
PX4_MAIN_MODE_AUTO = 4
PX4_SUB_MODE_AUTO_LAND = 6
ARDUCOPTER_LAND = 9
PX4_LAND_SPEED = 0.7
ARDUCOPTER_LAND_SPEED = 0.5
# PX4's COM_DISARM_LAND default: disarmed this long after landing.
PX4_DISARM_LAND_S = 2.0
# COMPONENT_ARM_DISARM param2 that forces a disarm in the air.
FORCE_DISARM = 21196
# Global frames by their altitude: above mean sea level, or above home.
AMSL_FRAMES = {mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT}
RELATIVE_FRAMES = {mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT}
# type_mask bits that drop the acceleration feed-forward.
ACCEL_IGNORED = (mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_AY_IGNORE
                 | mavlink.POSITION_TARGET_TYPEMASK_AZ_IGNORE)


def vec3(text):
    parts = [float(p) for p in text.split(",")]
    if len(parts) != 3 or not all(math.isfinite(p) for p in parts):
        raise argparse.ArgumentTypeError(f"expected three finite numbers x,y,z, got {text!r}")
    return parts


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--host", default="127.0.0.1", help="the member's address")
    p.add_argument("--port", type=int, required=True, help="the member's UDP port (P + i)")
    p.add_argument("--sysid", type=int, default=1, help="this vehicle's MAVLink system id")
    p.add_argument("--autopilot", choices=["px4", "ardupilot"], default="px4")
    p.add_argument("--start-ned", type=vec3, default=[0.0, 0.0, 0.0], help="start position, NED m")
    p.add_argument("--rate-hz", type=float, default=50.0, help="physics step")
    p.add_argument("--position-hz", type=float, default=None,
                   help="LOCAL_POSITION_NED rate (default: --rate-hz)")
    p.add_argument("--heartbeat-hz", type=float, default=1.0,
                   help="HEARTBEAT rate (PX4 and ArduPilot: 1 Hz)")
    p.add_argument("--attitude-hz", type=float, default=None,
                   help="ATTITUDE rate (default: --rate-hz)")
    p.add_argument("--jitter", type=float, default=0.1,
                   help="each packet leaves up to this fraction of its period late")
    p.add_argument("--late-prob", type=float, default=0.02,
                   help="chance that a packet is held back --late-periods more")
    p.add_argument("--late-periods", type=float, default=0.5,
                   help="how long a late packet is held back, in periods of its stream")
    p.add_argument("--dup-prob", type=float, default=0.02,
                   help="chance that a packet is sent twice")
    p.add_argument("--exact", action="store_true",
                   help="no jitter, no late or duplicated packets: every stream exactly at its rate")
    p.add_argument("--seed", type=int, default=None,
                   help="seed of the irregularities (default: --sysid)")
    p.add_argument("--require-arm", action="store_true",
                   help="move only when armed in OFFBOARD/GUIDED (otherwise track any setpoint)")
    p.add_argument("--silent-after", type=float, default=None,
                   help="stop sending this many seconds after the flight started (its first "
                        "setpoint that is not the initial hold; the member must name the loss)")
    p.add_argument("--mute", choices=["all", "heartbeat", "position"], default="all",
                   help="what --silent-after stops")
    p.add_argument("--max-s", type=float, default=30.0, help="hard bound on the run time")
    p.add_argument("--idle-exit-s", type=float, default=1.5,
                   help="exit this long after the last setpoint")
    p.add_argument("--signing-key", default=None,
                   help="a file of 64 hex digits: sign every frame sent with this key and take "
                        "only frames signed with it (pymavlink's MAVLink 2 signing)")
    p.add_argument("--inject-every", type=int, default=0,
                   help="with --signing-key: after every K-th position, also send from this "
                        "socket a position at --inject-ned unsigned and one signed with another "
                        "key (an attacker on the vehicle's own link)")
    p.add_argument("--inject-ned", type=vec3, default=[1000.0, 1000.0, -50.0],
                   help="the injected position, NED m")
    p.add_argument("--sys-status-hz", type=float, default=5.0,
                   help="SYS_STATUS rate (PX4 streams it at 5 Hz on an onboard link)")
    p.add_argument("--battery-start", type=float, default=100.0, help="battery_remaining at start, %%")
    p.add_argument("--battery-drain", type=float, default=0.0,
                   help="battery_remaining lost per second from the flight's start, %%/s "
                        "(voltage follows, 4S: 16.8 V full, 13.2 V empty)")
    p.add_argument("--failsafe-after", type=float, default=None,
                   help="this many seconds after the flight started, HEARTBEAT reports "
                        "MAV_STATE_CRITICAL (PX4 in a failsafe)")
    p.add_argument("--take-over-after", type=float, default=None,
                   help="this many seconds after it was first armed in OFFBOARD/GUIDED, a pilot "
                        "takes over: POSCTL (PX4) or LOITER (ArduCopter), setpoints ignored, hold")
    p.add_argument("--disarm-after", type=float, default=None,
                   help="this many seconds after it was first armed in OFFBOARD/GUIDED, the "
                        "vehicle disarms in flight and falls to its ground")
    p.add_argument("--ext-state-hz", type=float, default=1.0,
                   help="EXTENDED_SYS_STATE rate (landed_state)")
    p.add_argument("--refuse-takeoff", action="store_true",
                   help="answer every MAV_CMD_NAV_TAKEOFF with FAILED")
    p.add_argument("--stall-climb", action="store_true",
                   help="an accepted take-off climbs only halfway and stays there")
    p.add_argument("--refuse-fence", action="store_true",
                   help="answer every fence upload with MISSION_ACK MAV_MISSION_DENIED")
    p.add_argument("--home", type=vec3, default=None,
                   help="LAT,LON,ALT of its local NED origin (degrees, m AMSL): it has GPS, "
                        "streams GLOBAL_POSITION_INT and flies SET_POSITION_TARGET_GLOBAL_INT")
    return p.parse_args()


def read_key(path):
    with open(path, encoding="ascii") as f:
        return bytes.fromhex(f.read().strip())


# Signing timestamps: 10 microsecond units since 1 January 2015 (the MAVLink signing spec).
def signing_now():
    return int((time.time() - 1420070400) * 100 * 1000)


class Injector:
    """Forged positions for the vehicle's own system id, sent from the vehicle's socket: one
    unsigned, one signed with a key that is not the team's."""

    def __init__(self, args):
        self.every = args.inject_every
        self.ned = args.inject_ned
        self.unsigned = mavlink.MAVLink(None, srcSystem=args.sysid, srcComponent=1)
        self.wrong = mavlink.MAVLink(None, srcSystem=args.sysid, srcComponent=1)
        self.wrong.signing.secret_key = bytes(range(1, 33))
        self.wrong.signing.sign_outgoing = True
        self.wrong.signing.timestamp = signing_now()
        self.positions = 0
        self.sent = 0

    def after_position(self, conn, boot_ms):
        self.positions += 1
        if self.every <= 0 or self.positions % self.every:
            return
        for mav in (self.unsigned, self.wrong):
            msg = mav.local_position_ned_encode(boot_ms, *self.ned, 0.0, 0.0, 0.0)
            conn.write(msg.pack(mav))
            self.sent += 1


class Vehicle:
    def __init__(self, args):
        self.args = args
        self.pos = list(args.start_ned)
        self.vel = [0.0, 0.0, 0.0]
        self.acc = [0.0, 0.0, 0.0]
        self.setpoint = None  # (pos, vel, acc)
        self.custom_mode = 0
        self.armed = False
        self.setpoint_times = []
        self.setpoint_stamps_ms = []
        self.type_masks = set()
        self.frames = set()
        self.counts = {}
        self.bad_data = 0
        self.not_mavlink2 = 0
        self.wrong_target = 0
        self.commands = []
        self.member_sysids = set()
        # When this vehicle first sent HEARTBEAT and position (it is ready), on the wall clock.
        self.ready_unix = None
        self.streams = Streams(args)
        self.injector = Injector(args)
        self.lowest_battery = args.battery_start
        # When it was first armed in OFFBOARD/GUIDED, taken over, disarmed (its own clock, s).
        self.engaged_at = None
        self.taken_over_at = None
        self.disarmed_at = None
        # Where it holds once out of OFFBOARD/GUIDED (Position mode, sticks centred).
        self.hold = None
        self.setpoints_after_loss = 0
        # Setpoints that arrived after its first HEARTBEAT showing the take-over or the disarm
        # had left (the member can know only from then on).
        self.loss_shown = False
        self.setpoints_after_shown = 0
        # When the flight started: the first setpoint that is not the initial hold (its own
        # clock, s). --silent-after, --failsafe-after and --battery-drain count from it.
        self.first_setpoint = None
        self.flight_started_at = None
        # ArduCopter's take-off: where it armed (home), whether a take-off set auto_armed, the
        # climb's target height (NED z), when it completed (wall clock), and the position
        # targets that arrived on the ground before it or during the climb (not flown).
        self.home = None
        self.auto_armed = False
        self.takeoff_z = None
        self.climb_z = None
        self.airborne_unix = None
        self.setpoints_ignored_on_ground = 0
        self.setpoints_during_climb = 0
        self.flight_started_unix = None
        # Land mode (MAV_CMD_NAV_LAND accepted), whether it has taken off since arming, since
        # when it has been on the ground armed (its own clock), and how it was disarmed.
        self.landing = False
        self.took_off = False
        self.on_ground_since = None
        self.disarmed_on_ground_unix = None
        self.disarmed_by = None
        # GPS: PX4's map projection about home, and the global targets it could not fly.
        self.home_projection = (None if args.home is None
                                else MapProjection(args.home[0], args.home[1]))
        self.global_refused = 0
        # The geofence it holds (MISSION_ITEM_INT messages), the one being uploaded, and counts.
        self.fence = []
        self.fence_incoming = None
        self.fence_expected = 0
        self.fence_acks = {}

    def ardupilot(self):
        return self.args.autopilot == "ardupilot"

    def on_ground(self):
        """landed_state ON_GROUND: at its frame's ground (NED z = 0), at rest."""
        return (self.pos[2] >= -GROUND_TOLERANCE_M
                and math.sqrt(sum(v * v for v in self.vel)) <= GROUND_SPEED_MPS)

    def ground_handling(self):
        """ArduCopter armed on the ground before a take-off: position targets are not flown."""
        return self.ardupilot() and not self.auto_armed and self.on_ground()

    def climbing(self):
        return self.takeoff_z is not None and self.airborne_unix is None and self.armed

    def landed_state(self):
        if self.on_ground():
            return mavlink.MAV_LANDED_STATE_ON_GROUND
        if self.climbing():
            return mavlink.MAV_LANDED_STATE_TAKEOFF
        if self.landing and self.armed:
            return mavlink.MAV_LANDED_STATE_LANDING
        return mavlink.MAV_LANDED_STATE_IN_AIR

    def since_flight(self, now):
        """Seconds since the flight started, or None before."""
        return None if self.flight_started_at is None else now - self.flight_started_at

    def on_setpoint_value(self, setpoint, now):
        """Notes the flight's start: a setpoint 1 mm or 1 mm/s (or 1 mm/s^2) away from the first
        one, which the member repeats while its team gets ready."""
        if self.first_setpoint is None:
            self.first_setpoint = setpoint
        if self.flight_started_at is None and any(
                abs(a - b) > 1e-3 for new, first in zip(setpoint, self.first_setpoint)
                for a, b in zip(new, first)):
            self.flight_started_at = now
            self.flight_started_unix = time.time()
            print(f"mavlink_vehicle {self.args.sysid}: flight started at {now:.2f} s",
                  file=sys.stderr, flush=True)

    def guided(self):
        if self.args.autopilot == "px4":
            return (self.custom_mode >> 16) & 0xFF == PX4_MAIN_MODE_OFFBOARD
        return self.custom_mode == ARDUCOPTER_GUIDED

    def on_message(self, conn, msg, now):
        kind = msg.get_type()
        if kind == "BAD_DATA":
            self.bad_data += 1
            return
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if msg.get_msgbuf()[0] != 0xFD:
            self.not_mavlink2 += 1
        self.member_sysids.add(msg.get_srcSystem())
        if kind in ("SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT"):
            if msg.target_system != self.args.sysid:
                self.wrong_target += 1
                return
            target = self.target_ned(msg)
            if target is None:
                self.global_refused += 1
                return
            self.setpoint_times.append(now)
            if self.armed and self.ground_handling():
                self.setpoints_ignored_on_ground += 1
            elif self.climbing():
                self.setpoints_during_climb += 1
            self.setpoint_stamps_ms.append(msg.time_boot_ms)
            if self.taken_over_at is not None or self.disarmed_at is not None:
                self.setpoints_after_loss += 1
            if self.loss_shown:
                self.setpoints_after_shown += 1
            self.type_masks.add(msg.type_mask)
            self.frames.add(msg.coordinate_frame)
            acc = ([0.0, 0.0, 0.0] if kind == "SET_POSITION_TARGET_GLOBAL_INT"
                   and msg.type_mask & ACCEL_IGNORED == ACCEL_IGNORED else [msg.afx, msg.afy, msg.afz])
            self.setpoint = (target, [msg.vx, msg.vy, msg.vz], acc)
            self.on_setpoint_value(self.setpoint, now)
        elif kind == "COMMAND_LONG":
            self.on_command(conn, msg, now)
        elif (kind.startswith("MISSION_")
              and getattr(msg, "mission_type", None) == mavlink.MAV_MISSION_TYPE_FENCE):
            self.on_fence(conn, msg)

    def on_fence(self, conn, msg):
        """The fence side of the mission protocol (upload, download)."""
        kind = msg.get_type()
        fence = mavlink.MAV_MISSION_TYPE_FENCE
        me = (msg.get_srcSystem(), msg.get_srcComponent())
        if kind == "MISSION_COUNT":
            if self.args.refuse_fence:
                conn.mav.mission_ack_send(*me, mavlink.MAV_MISSION_DENIED, fence)
                return
            self.fence_incoming, self.fence_expected = [], msg.count
            if msg.count == 0:
                self.fence, self.fence_incoming = [], None
                conn.mav.mission_ack_send(*me, mavlink.MAV_MISSION_ACCEPTED, fence)
                return
            conn.mav.mission_request_int_send(*me, 0, fence)
        elif kind == "MISSION_ITEM_INT" and self.fence_incoming is not None:
            if msg.seq != len(self.fence_incoming):
                return
            self.fence_incoming.append(msg)
            if len(self.fence_incoming) < self.fence_expected:
                conn.mav.mission_request_int_send(*me, len(self.fence_incoming), fence)
                return
            result = (mavlink.MAV_MISSION_ACCEPTED if polygons_whole(self.fence_incoming)
                      else mavlink.MAV_MISSION_INVALID)
            if result == mavlink.MAV_MISSION_ACCEPTED:
                self.fence = self.fence_incoming
            self.fence_incoming = None
            conn.mav.mission_ack_send(*me, result, fence)
        elif kind == "MISSION_REQUEST_LIST":
            conn.mav.mission_count_send(*me, len(self.fence), fence)
        elif kind == "MISSION_REQUEST_INT" and msg.seq < len(self.fence):
            i = self.fence[msg.seq]
            conn.mav.mission_item_int_send(*me, i.seq, i.frame, i.command, 0, 0, i.param1,
                                           i.param2, i.param3, i.param4, i.x, i.y, i.z, fence)
        elif kind == "MISSION_ACK":
            self.fence_acks[msg.type] = self.fence_acks.get(msg.type, 0) + 1

    def target_ned(self, msg):
        """A target's position in the local NED frame; None for a global one it cannot fly (no
        GPS, or a frame it does not know)."""
        if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
            return [msg.x, msg.y, msg.z]
        if self.home_projection is None:
            return None
        if msg.coordinate_frame in AMSL_FRAMES:
            down = self.args.home[2] - msg.alt
        elif msg.coordinate_frame in RELATIVE_FRAMES:
            down = -msg.alt
        else:
            return None
        north, east = self.home_projection.project(msg.lat_int / 1e7, msg.lon_int / 1e7)
        return [north, east, down]

    def global_position(self):
        """(lat, lon, alt AMSL) of where it is (PX4's reprojection of its local position)."""
        lat, lon = self.home_projection.reproject(self.pos[0], self.pos[1])
        return lat, lon, self.args.home[2] - self.pos[2]

    def on_command(self, conn, msg, now):
        streaming = bool(self.setpoint_times) and now - self.setpoint_times[-1] < OFFBOARD_LOSS_S
        result = mavlink.MAV_RESULT_DENIED
        if msg.command == mavlink.MAV_CMD_DO_SET_MODE and streaming:
            if self.args.autopilot == "px4":
                self.custom_mode = (int(msg.param2) & 0xFF) << 16 | (int(msg.param3) & 0xFF) << 24
            else:
                self.custom_mode = int(msg.param2)
            if self.guided():
                self.hold = None
            result = mavlink.MAV_RESULT_ACCEPTED
        elif msg.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM and msg.param1 == 1.0:
            if self.guided():
                self.armed = True
                self.home = list(self.pos)
                result = mavlink.MAV_RESULT_ACCEPTED
        elif msg.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            # In the air only when forced (21196); on the ground always.
            if self.armed and (self.on_ground() or msg.param2 == FORCE_DISARM):
                self.disarm("command")
                result = mavlink.MAV_RESULT_ACCEPTED
            elif self.armed:
                result = mavlink.MAV_RESULT_FAILED
        elif msg.command == mavlink.MAV_CMD_NAV_TAKEOFF:
            result = self.on_takeoff(msg.param7)
        elif msg.command == mavlink.MAV_CMD_NAV_LAND:
            result = self.on_land()
        # The wall clock (not `now`, this process's own): tests compare it across vehicles.
        self.commands.append({"command": msg.command, "param1": msg.param1, "param2": msg.param2,
                              "confirmation": msg.confirmation, "result": result,
                              "t_unix": time.time()})
        conn.mav.command_ack_send(msg.command, result)

    def on_takeoff(self, altitude_m):
        """ArduCopter's Mode::do_user_takeoff: armed, GUIDED, landed, upwards; else FAILED."""
        if not self.ardupilot():
            return mavlink.MAV_RESULT_UNSUPPORTED
        home = self.home
        if (self.args.refuse_takeoff or not self.armed or not self.guided() or home is None
                or not self.on_ground() or not math.isfinite(altitude_m)
                or altitude_m <= home[2] - self.pos[2]):
            return mavlink.MAV_RESULT_FAILED
        self.auto_armed = True
        self.takeoff_z = home[2] - altitude_m
        self.climb_z = self.pos[2]
        print(f"mavlink_vehicle {self.args.sysid}: take-off to {altitude_m:.2f} m",
              file=sys.stderr, flush=True)
        return mavlink.MAV_RESULT_ACCEPTED

    def climb(self, dt):
        """The take-off's target height rises at ARDUCOPTER_TAKEOFF_SPEED (halfway only with
        --stall-climb); complete once both it and the vehicle are at the altitude. Returns the
        target (NED) to track."""
        top = self.takeoff_z
        if self.args.stall_climb:
            top = 0.5 * (self.home[2] + self.takeoff_z)
        self.climb_z = max(top, self.climb_z - ARDUCOPTER_TAKEOFF_SPEED * dt)
        if self.climb_z == self.takeoff_z and abs(self.pos[2] - self.takeoff_z) <= 0.05:
            self.airborne_unix = time.time()
            print(f"mavlink_vehicle {self.args.sysid}: take-off complete", file=sys.stderr,
                  flush=True)
        return [self.home[0], self.home[1], self.climb_z]

    def on_land(self):
        """MAV_CMD_NAV_LAND: Land mode where it is, armed only."""
        if not self.armed:
            return mavlink.MAV_RESULT_FAILED
        self.custom_mode = (ARDUCOPTER_LAND if self.ardupilot() else
                            PX4_MAIN_MODE_AUTO << 16 | PX4_SUB_MODE_AUTO_LAND << 24)
        self.landing = True
        self.hold = [self.pos[0], self.pos[1], 0.0]
        print(f"mavlink_vehicle {self.args.sysid}: landing", file=sys.stderr, flush=True)
        return mavlink.MAV_RESULT_ACCEPTED

    def disarm(self, by):
        self.armed = False
        self.disarmed_by = by
        if self.on_ground():
            self.disarmed_on_ground_unix = time.time()
        print(f"mavlink_vehicle {self.args.sysid}: disarmed ({by})", file=sys.stderr, flush=True)

    def auto_disarm(self, now):
        """Disarmed by itself on the ground after a flight: PX4 after COM_DISARM_LAND (any
        mode), ArduCopter at touchdown in LAND."""
        if not self.armed or not self.on_ground():
            self.on_ground_since = None
            self.took_off |= self.armed and not self.on_ground()
            return
        if self.on_ground_since is None:
            self.on_ground_since = now
        if not self.took_off:
            return
        if self.ardupilot() and self.landing:
            self.disarm("autopilot")
        elif not self.ardupilot() and now - self.on_ground_since >= PX4_DISARM_LAND_S:
            self.disarm("autopilot")

    def leave_guided(self, mode):
        """Out of OFFBOARD/GUIDED into `mode`: hold where it is from now on."""
        self.custom_mode = mode
        self.hold = list(self.pos)

    def take_over(self, now):
        """A pilot's take-over or disarm, once due (counted from the first engagement)."""
        if self.engaged_at is None and self.armed and self.guided():
            self.engaged_at = now
        if self.engaged_at is None:
            return
        a = self.args
        since = now - self.engaged_at
        if a.take_over_after is not None and since >= a.take_over_after and self.taken_over_at is None:
            self.taken_over_at = now
            self.leave_guided(PX4_MAIN_MODE_POSCTL << 16 if a.autopilot == "px4" else ARDUCOPTER_LOITER)
            print(f"mavlink_vehicle {a.sysid}: taken over at {now:.2f} s", file=sys.stderr, flush=True)
        if a.disarm_after is not None and since >= a.disarm_after and self.disarmed_at is None:
            self.disarmed_at = now
            self.armed = False
            print(f"mavlink_vehicle {a.sysid}: disarmed at {now:.2f} s", file=sys.stderr, flush=True)

    def step(self, dt, now):
        self.take_over(now)
        self.auto_disarm(now)
        if self.args.autopilot == "px4" and self.guided() and (
                not self.setpoint_times or now - self.setpoint_times[-1] > OFFBOARD_LOSS_S):
            self.leave_guided(PX4_MAIN_MODE_POSCTL << 16)  # COM_OF_LOSS_T, then Position mode
        flying = self.setpoint is not None and self.hold is None and (
            not self.args.require_arm or (self.armed and self.guided()))
        motors_off = self.disarmed_at is not None or (
            self.args.require_arm and not self.armed and self.home is not None)
        if motors_off:
            # Motors off (disarmed in flight, or on the ground at the end): free fall (NED z
            # down) to the ground, then at rest.
            self.acc = [0.0, 0.0, GRAVITY if self.pos[2] < 0.0 else 0.0]
        elif self.climbing():
            target = self.climb(dt)
            self.acc = [KP * (target[k] - self.pos[k]) - KD * self.vel[k] for k in range(3)]
        elif self.landing:
            # Land mode: hold x, y and descend at the land speed to the ground.
            speed = ARDUCOPTER_LAND_SPEED if self.ardupilot() else PX4_LAND_SPEED
            self.acc = [KP * (self.hold[k] - self.pos[k]) - KD * self.vel[k] for k in range(2)]
            self.acc.append(KD * (speed - self.vel[2]))
        elif self.hold is not None:
            self.acc = [KP * (self.hold[k] - self.pos[k]) - KD * self.vel[k] for k in range(3)]
        elif flying and not (self.armed and self.ground_handling()):
            p, v, a = self.setpoint
            self.acc = [a[k] + KP * (p[k] - self.pos[k]) + KD * (v[k] - self.vel[k])
                        for k in range(3)]
        else:
            self.acc = [0.0, 0.0, 0.0]
        # Semi-implicit Euler at the fixed step: the vehicle's own time, not the wall clock.
        self.vel = [self.vel[k] + self.acc[k] * dt for k in range(3)]
        self.pos = [self.pos[k] + self.vel[k] * dt for k in range(3)]
        # The ground holds it: nothing goes below NED z = 0.
        if self.pos[2] >= 0.0 and self.vel[2] >= 0.0 and self.was_above_ground(dt):
            self.pos[2] = 0.0
            self.vel = [0.0, 0.0, 0.0] if motors_off or self.landing else [
                self.vel[0], self.vel[1], 0.0]

    def was_above_ground(self, dt):
        """Whether it came down to the ground this step (a vehicle started below NED z = 0, as
        none of the tests' is, is left alone)."""
        return self.pos[2] - self.vel[2] * dt <= 0.0

    def build(self, conn, kind, boot_ms, silent, now):
        """The `kind` message with the vehicle's state now, or None while that stream is muted."""
        if self.ready_unix is None:
            self.ready_unix = time.time()
        mute = self.args.mute
        muted = {"heartbeat": ("HEARTBEAT",),
                 "position": ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT")}
        if silent and (mute == "all" or kind in muted[mute]):
            return None
        if kind == "HEARTBEAT":
            autopilot = (mavlink.MAV_AUTOPILOT_PX4 if self.args.autopilot == "px4"
                         else mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA)
            base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            if self.armed:
                base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
            since = self.since_flight(now)
            failsafe = (self.args.failsafe_after is not None and since is not None
                        and since >= self.args.failsafe_after)
            state = mavlink.MAV_STATE_CRITICAL if failsafe else mavlink.MAV_STATE_ACTIVE
            return conn.mav.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, autopilot, base,
                                             self.custom_mode, state)
        if kind == "SYS_STATUS":
            pct = max(0.0, self.args.battery_start
                      - self.args.battery_drain * (self.since_flight(now) or 0.0))
            self.lowest_battery = min(self.lowest_battery, pct)
            millivolts = int(13200 + 3600 * pct / 100.0)
            return conn.mav.sys_status_encode(0, 0, 0, 0, millivolts, -1, int(pct),
                                              0, 0, 0, 0, 0, 0)
        if kind == "EXTENDED_SYS_STATE":
            return conn.mav.extended_sys_state_encode(mavlink.MAV_VTOL_STATE_UNDEFINED,
                                                      self.landed_state())
        if kind == "LOCAL_POSITION_NED":
            return conn.mav.local_position_ned_encode(boot_ms, *self.pos, *self.vel)
        if kind == "GLOBAL_POSITION_INT":
            lat, lon, alt = self.global_position()
            cm_s = [int(round(v * 100.0)) for v in self.vel]
            # hdg UINT16_MAX: unknown (the point mass has no heading).
            return conn.mav.global_position_int_encode(
                boot_ms, int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000.0)),
                int(round(-self.pos[2] * 1000.0)), *cm_s, 65535)
        # Small-angle attitude that would produce the commanded horizontal acceleration.
        roll = math.atan2(self.acc[1], GRAVITY)
        pitch = -math.atan2(self.acc[0], GRAVITY)
        return conn.mav.attitude_encode(boot_ms, roll, pitch, 0.0, 0.0, 0.0, 0.0)

    def summary(self, conn, went_silent_at, exit_reason):
        t = self.setpoint_times
        rate = (len(t) - 1) / (t[-1] - t[0]) if len(t) > 1 and t[-1] > t[0] else None
        # The same rate on the sender's clock (the setpoints' time_boot_ms): what the member sent,
        # free of this process's own scheduling delays on a loaded machine.
        ms = self.setpoint_stamps_ms
        stamp_rate = ((len(ms) - 1) * 1000.0 / (ms[-1] - ms[0])
                      if len(ms) > 1 and ms[-1] > ms[0] else None)
        return {
            "sysid": self.args.sysid,
            "setpoints_received": len(t),
            "setpoint_rate_hz": rate,
            "setpoint_rate_by_stamp_hz": stamp_rate,
            "setpoint_window_s": (t[-1] - t[0]) if t else None,
            "type_masks": sorted(self.type_masks),
            "frames": sorted(self.frames),
            "bad_data": self.bad_data,
            "receive_errors": conn.mav.total_receive_errors,
            "packets_received": conn.mav.total_packets_received,
            "not_mavlink2": self.not_mavlink2,
            "wrong_target": self.wrong_target,
            "messages": self.counts,
            "member_sysids": sorted(self.member_sysids),
            "commands": self.commands,
            "armed": self.armed,
            "custom_mode": self.custom_mode,
            "final_position_ned": self.pos,
            "final_position_global": (None if self.home_projection is None
                                      else list(self.global_position())),
            "global_targets_refused": self.global_refused,
            "fence": [[i.command, i.param1, i.x, i.y] for i in self.fence],
            "fence_acks_received": self.fence_acks,
            "last_setpoint_ned": self.setpoint[0] if self.setpoint else None,
            "ready_unix": self.ready_unix,
            "sent": self.streams.sent,
            "late_packets": self.streams.late,
            "duplicated_packets": self.streams.duplicated,
            "went_silent_at_s": went_silent_at,
            "exit": exit_reason,
            "signing": None if self.args.signing_key is None else {
                "good": conn.mav.signing.goodsig_count,
                "bad": conn.mav.signing.badsig_count,
                "unsigned": conn.mav.signing.unsigned_count,
                "rejected": conn.mav.signing.reject_count,
            },
            "injected": self.injector.sent,
            "lowest_battery_pct": int(self.lowest_battery),
            "engaged_at_s": self.engaged_at,
            "taken_over_at_s": self.taken_over_at,
            "disarmed_at_s": self.disarmed_at,
            "setpoints_after_loss": self.setpoints_after_loss,
            "setpoints_after_shown": self.setpoints_after_shown,
            "last_setpoint_s": self.setpoint_times[-1] if self.setpoint_times else None,
            "flight_started_at_s": self.flight_started_at,
            "flight_started_unix": self.flight_started_unix,
            "airborne_unix": self.airborne_unix,
            "setpoints_ignored_on_ground": self.setpoints_ignored_on_ground,
            "setpoints_during_climb": self.setpoints_during_climb,
            "disarmed_on_ground_unix": self.disarmed_on_ground_unix,
            "disarmed_by": self.disarmed_by,
            "landed_state": self.landed_state(),
            "height_m": -self.pos[2],
        }


class Streams:
    """When each stream is next due, and the packets waiting to leave (by send time)."""

    def __init__(self, args):
        self.args = args
        self.rng = random.Random(args.sysid if args.seed is None else args.seed)
        self.periods = {"HEARTBEAT": 1.0 / args.heartbeat_hz,
                        "SYS_STATUS": 1.0 / args.sys_status_hz,
                        "EXTENDED_SYS_STATE": 1.0 / args.ext_state_hz,
                        "LOCAL_POSITION_NED": 1.0 / (args.position_hz or args.rate_hz),
                        "ATTITUDE": 1.0 / (args.attitude_hz or args.rate_hz)}
        if args.home is not None:
            self.periods["GLOBAL_POSITION_INT"] = self.periods["LOCAL_POSITION_NED"]
        # The index of the last period each stream was sent for (-1: none yet).
        self.last = {kind: -1 for kind in self.periods}
        self.queue = []  # heap of (send_at, order, msg, duplicate)
        self.order = 0
        self.sent = {kind: 0 for kind in self.periods}
        self.late = 0
        self.duplicated = 0

    def delay(self, period):
        """How late this packet leaves, and whether it goes twice. Three draws per packet
        whatever the options, so --exact changes nothing else of a seeded run."""
        jitter, late, dup = self.rng.random(), self.rng.random(), self.rng.random()
        if self.args.exact:
            return 0.0, False
        d = jitter * self.args.jitter * period
        if late < self.args.late_prob:
            d += self.args.late_periods * period
            self.late += 1
        return d, dup < self.args.dup_prob

    def schedule(self, vehicle, conn, now, boot_ms, silent):
        """Queue each stream's packet once its period has come (a stalled loop skips periods,
        as PX4's streams do, rather than bursting)."""
        for kind, period in self.periods.items():
            k = math.floor(now / period)
            if k <= self.last[kind]:
                continue
            self.last[kind] = k
            msg = vehicle.build(conn, kind, boot_ms, silent, now)
            if msg is None:
                continue
            d, dup = self.delay(period)
            heapq.heappush(self.queue, (now + d, self.order, msg, False))
            self.order += 1
            if dup:
                heapq.heappush(self.queue, (now + d, self.order, msg, True))
                self.order += 1

    def flush(self, vehicle, conn, now):
        while self.queue and self.queue[0][0] <= now:
            _, _, msg, duplicate = heapq.heappop(self.queue)
            if duplicate:
                # The very datagram again (same sequence number, and when signed the same
                # signature timestamp: a replay), as a duplicating link does.
                conn.write(msg.get_msgbuf())
                self.duplicated += 1
            else:
                conn.mav.send(msg)
                self.sent[msg.get_type()] += 1
                if msg.get_type() == "HEARTBEAT" and (vehicle.taken_over_at is not None
                                                     or vehicle.disarmed_at is not None):
                    vehicle.loss_shown = True
                if msg.get_type() == "LOCAL_POSITION_NED":
                    vehicle.injector.after_position(conn, msg.time_boot_ms)

    def next_at(self):
        return self.queue[0][0] if self.queue else math.inf


def polygons_whole(items):
    """Every polygon vertex item carries its polygon's vertex count, and each polygon has that
    many vertices in a row (the geofence items' definition)."""
    polygon = (mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
               mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION)
    k = 0
    while k < len(items):
        i = items[k]
        if i.command not in polygon:
            k += 1
            continue
        n = int(i.param1)
        run = items[k:k + n]
        if n < 3 or len(run) < n or any(j.command != i.command or int(j.param1) != n for j in run):
            return False
        k += n
    return True


def drain(conn, vehicle, now):
    # Bounded: at most this many messages per tick (a flood cannot stall the loop).
    for _ in range(1000):
        msg = conn.recv_msg()
        if msg is None:
            return
        vehicle.on_message(conn, msg, now)


def main():
    args = parse_args()
    rates = [args.rate_hz, args.heartbeat_hz, args.attitude_hz or args.rate_hz,
             args.position_hz or args.rate_hz]
    odds = [args.jitter, args.late_prob, args.late_periods, args.dup_prob]
    if (not (0 < args.port < 65536) or not all(0 < r <= 1000 for r in rates)
            or args.max_s <= 0 or not all(0 <= x <= 10 for x in odds)):
        print("mavlink_vehicle: --port, a rate, an irregularity or --max-s out of range",
              file=sys.stderr)
        return 2
    conn = mavutil.mavlink_connection(f"udpout:{args.host}:{args.port}",
                                      source_system=args.sysid, source_component=1)
    if args.signing_key is not None:
        # As a PX4 with a key provisioned: outgoing frames signed, incoming ones must be.
        conn.setup_signing(read_key(args.signing_key), sign_outgoing=True,
                           allow_unsigned_callback=None, initial_timestamp=signing_now(),
                           link_id=0)
    vehicle = Vehicle(args)
    # Tests start the team once every vehicle says this (Python starts slowly on a loaded host).
    print(f"mavlink_vehicle {args.sysid}: sending to {args.host}:{args.port}",
          file=sys.stderr, flush=True)
    dt = 1.0 / args.rate_hz
    start = time.monotonic()
    went_silent_at = None
    exit_reason = "max-s"
    k = 0
    while True:
        now = time.monotonic() - start
        if now >= args.max_s:
            break
        t = vehicle.setpoint_times
        if t and now - t[-1] > args.idle_exit_s:
            exit_reason = "idle"
            break
        if now >= k * dt:
            drain(conn, vehicle, now)
            vehicle.step(dt, now)
            since = vehicle.since_flight(now)
            silent = (args.silent_after is not None and since is not None
                      and since >= args.silent_after)
            if silent and went_silent_at is None:
                went_silent_at = now
                print(f"mavlink_vehicle {args.sysid}: silent ({args.mute}) at {now:.2f} s",
                      file=sys.stderr, flush=True)
            vehicle.streams.schedule(vehicle, conn, now, int(k * dt * 1000), silent)
            k += 1
        vehicle.streams.flush(vehicle, conn, now)
        # Paced on the wall clock, one fixed step per tick (late ticks are not skipped); woken
        # early for a packet due between two ticks.
        wake = start + min(k * dt, vehicle.streams.next_at())
        wait = wake - time.monotonic()
        if wait > 0:
            time.sleep(wait)
    print(json.dumps(vehicle.summary(conn, went_silent_at, exit_reason)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
