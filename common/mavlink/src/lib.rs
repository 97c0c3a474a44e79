//! The MAVLink vehicle plant: a member's link to a PX4 or ArduPilot vehicle. The
//! member reads the vehicle's measured state (HEARTBEAT, LOCAL_POSITION_NED, ATTITUDE) and sends
//! it setpoints (SET_POSITION_TARGET_LOCAL_NED with velocity and acceleration feed-forward) and a
//! HEARTBEAT once a second.
//!
//! Layers: `ned` and `global` (frame conversion: local NED, or latitude and longitude with an
//! `[origin]`), `health` (loss detection), `takeover` (a vehicle leaving
//! OFFBOARD/GUIDED, named by `flight_mode`), `arming` (`--arm` sequence), `takeoff` and
//! `landing` (ArduCopter's take-off, `--disarm-at-end`; `flight_ends` holds both) and
//! `fence` (`--upload-fence`: the mission protocol's fence side) and `messages` (what is
//! sent) are pure; `vehicle` combines them into [`MavlinkVehicle`], still
//! without I/O, driven by the caller's clock; `udp` is the socket. `setpoint` (pure) and `plant`
//! put them behind the member's `Vehicle` seam (cdm-runtime): [`MavlinkPlant`]. The encoding is
//! the `mavlink` crate's (MAVLink 2, common dialect).

pub mod arming;
pub mod battery;
pub mod fence;
pub mod flight_ends;
pub mod flight_mode;
pub mod global;
pub mod health;
pub mod landing;
pub mod messages;
pub mod ned;
pub mod plant;
pub mod report;
pub mod setpoint;
pub mod signing;
pub mod takeoff;
pub mod takeover;
pub mod team_arm;
pub mod udp;
pub mod vehicle;

pub use arming::{ArmAction, ArmError, ArmStage, Autopilot};
pub use battery::BatteryFigures;
pub use flight_mode::FlightMode;
pub use global::VehicleFrame;
pub use health::{
    LinkFault, LinkTimeouts, PositionStream, DEFAULT_HEARTBEAT_TIMEOUT, DEFAULT_POSITION_TIMEOUT,
};
pub use messages::Setpoint;
pub use ned::VehicleOrigin;
pub use plant::{
    ArmProgress, LinkFigures, LinkRead, MavlinkPlant, PlantConfig, PlantError, SendTimes,
};
pub use report::{Reporting, VehicleReport};
pub use setpoint::FeedForward;
pub use signing::{KeyError, SigningKey};
pub use team_arm::{before_start, TeamArmError};
pub use udp::{member_addr, Received, UdpError, UdpLink, DEFAULT_BASE_PORT};
pub use vehicle::{
    Attitude, AttitudeFigures, MavlinkVehicle, MeasuredState, VehicleConfig, VehicleError,
};
