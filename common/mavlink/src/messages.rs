//! The MAVLink messages the member sends, built from plain values (outgoing direction only;
//! decoding is in `vehicle`). The encoding itself is the `mavlink` crate's.

use mavlink::dialects::common::{
    MavAutopilot, MavCmd, MavFrame, MavMessage, MavModeFlag, MavState, MavType,
    PositionTargetTypemask, COMMAND_LONG_DATA, HEARTBEAT_DATA, SET_POSITION_TARGET_LOCAL_NED_DATA,
};

use crate::arming::ArmAction;
use crate::ned::{enu_to_ned_vector, to_f32, VehicleOrigin};
use cdm_math::Vec3;

/// The member's MAVLink system id. Autopilots default to 1 and ground stations to 255; 245 is
/// what MAVSDK uses for a ground station, so it collides with neither default.
pub const MEMBER_SYSTEM_ID: u8 = 245;
/// MAV_COMP_ID_ONBOARD_COMPUTER: the member runs beside the flight controller.
pub const MEMBER_COMPONENT_ID: u8 = 191;

/// SET_POSITION_TARGET_LOCAL_NED's type_mask: position, velocity and acceleration are all used
/// (feed-forward), yaw and yaw rate are ignored (the scenario has no heading). Value 3072.
pub const SETPOINT_TYPE_MASK: PositionTargetTypemask = PositionTargetTypemask::from_bits_truncate(
    PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE.bits()
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE.bits(),
);

/// A desired state in scenario coordinates (ENU): r_d and its first three derivatives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setpoint {
    pub position: Vec3,
    pub velocity: Vec3,
    pub acceleration: Vec3,
    /// Not sent (SET_POSITION_TARGET_LOCAL_NED has no jerk field): the member publishes it with
    /// its measured state, as the feed-forward its out-neighbours extrapolate with
    /// (`setpoint::measured_state`).
    pub jerk: Vec3,
}

/// The vehicle a message is addressed to (from its HEARTBEAT's header).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Target {
    pub system: u8,
    pub component: u8,
}

/// The member's own HEARTBEAT: an onboard controller, not an autopilot.
pub fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// SET_POSITION_TARGET_LOCAL_NED for `sp`, converted to the vehicle's NED frame.
pub fn position_target(
    target: Target,
    time_boot_ms: u32,
    origin: &VehicleOrigin,
    sp: &Setpoint,
) -> MavMessage {
    let [x, y, z] = to_f32(&origin.enu_to_ned(&sp.position));
    let [vx, vy, vz] = to_f32(&enu_to_ned_vector(&sp.velocity));
    let [afx, afy, afz] = to_f32(&enu_to_ned_vector(&sp.acceleration));
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        time_boot_ms,
        x,
        y,
        z,
        vx,
        vy,
        vz,
        afx,
        afy,
        afz,
        yaw: 0.0,
        yaw_rate: 0.0,
        type_mask: SETPOINT_TYPE_MASK,
        target_system: target.system,
        target_component: target.component,
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
    })
}

/// The COMMAND_LONG of an `--arm`, take-off or landing step. `confirmation` counts retransmissions (MAVLink's
/// command protocol: 0 for the first, +1 for each repeat).
pub fn command(target: Target, action: ArmAction, confirmation: u8) -> MavMessage {
    let custom = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED.bits();
    // COMMAND_LONG params are f32 by definition; mode numbers are small integers, exact in f32.
    let mut p7 = 0.0;
    let (cmd, p1, p2, p3) = match action {
        ArmAction::SetMode {
            custom_mode,
            sub_mode,
        } => (
            MavCmd::MAV_CMD_DO_SET_MODE,
            f32::from(custom),
            custom_mode as f32,
            sub_mode as f32,
        ),
        ArmAction::Arm => (MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0, 0.0, 0.0),
        // param2 = 0: not forced (21196 would disarm in the air).
        ArmAction::Disarm => (MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 0.0, 0.0, 0.0),
        // Latitude, longitude and altitude 0: land where the vehicle is (its Land mode).
        ArmAction::Land => (MavCmd::MAV_CMD_NAV_LAND, 0.0, 0.0, 0.0),
        ArmAction::Takeoff { altitude_m } => {
            p7 = altitude_m;
            (MavCmd::MAV_CMD_NAV_TAKEOFF, 0.0, 0.0, 0.0)
        }
    };
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: p1,
        param2: p2,
        param3: p3,
        param4: 0.0,
        param5: 0.0,
        param6: 0.0,
        param7: p7,
        command: cmd,
        target_system: target.system,
        target_component: target.component,
        confirmation,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::{MavHeader, MavlinkReader};

    /// Encode with the crate and decode the bytes again (MAVLink 2, checksum checked).
    fn round_trip(msg: &MavMessage) -> MavMessage {
        let mut bytes = Vec::new();
        let header = MavHeader {
            system_id: u32::from(MEMBER_SYSTEM_ID),
            component_id: MEMBER_COMPONENT_ID,
            sequence: 7,
        };
        mavlink::write_v2_msg(&mut bytes, header, msg).expect("encode");
        let mut reader = MavlinkReader::new(bytes.as_slice());
        let (h, back) = reader.read_any_message::<MavMessage>().expect("decode");
        assert_eq!(h, header);
        back
    }

    #[test]
    fn type_mask_uses_position_velocity_and_acceleration() {
        assert_eq!(SETPOINT_TYPE_MASK.bits(), 3072);
    }

    #[test]
    fn position_target_is_ned_after_the_origin() {
        let origin = VehicleOrigin(Vec3::new(10.0, 20.0, 0.0));
        let sp = Setpoint {
            position: Vec3::new(12.0, 21.0, 3.0),
            velocity: Vec3::new(0.5, 1.0, 0.25),
            acceleration: Vec3::new(0.0, -0.5, 1.0),
            jerk: Vec3::new(9.0, 9.0, 9.0),
        };
        let target = Target {
            system: 1,
            component: 1,
        };
        let MavMessage::SET_POSITION_TARGET_LOCAL_NED(d) =
            round_trip(&position_target(target, 1234, &origin, &sp))
        else {
            panic!("wrong message type");
        };
        assert_eq!((d.x, d.y, d.z), (1.0, 2.0, -3.0));
        assert_eq!((d.vx, d.vy, d.vz), (1.0, 0.5, -0.25));
        assert_eq!((d.afx, d.afy, d.afz), (-0.5, 0.0, -1.0));
        assert_eq!(d.type_mask, SETPOINT_TYPE_MASK);
        assert_eq!(d.coordinate_frame, MavFrame::MAV_FRAME_LOCAL_NED);
        assert_eq!(
            (d.target_system, d.target_component, d.time_boot_ms),
            (1, 1, 1234)
        );
    }

    #[test]
    fn mode_and_arm_commands_carry_the_documented_params() {
        let target = Target {
            system: 2,
            component: 1,
        };
        let set_mode = ArmAction::SetMode {
            custom_mode: 6,
            sub_mode: 0,
        };
        let MavMessage::COMMAND_LONG(c) = round_trip(&command(target, set_mode, 0)) else {
            panic!("wrong message type");
        };
        assert_eq!(c.command, MavCmd::MAV_CMD_DO_SET_MODE);
        assert_eq!((c.param1, c.param2, c.param3), (1.0, 6.0, 0.0));
        assert_eq!((c.target_system, c.confirmation), (2, 0));
        let MavMessage::COMMAND_LONG(a) = round_trip(&command(target, ArmAction::Arm, 2)) else {
            panic!("wrong message type");
        };
        assert_eq!(a.command, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM);
        assert_eq!((a.param1, a.confirmation), (1.0, 2));
        let roundtrip = |action| match round_trip(&command(target, action, 0)) {
            MavMessage::COMMAND_LONG(c) => c,
            other => panic!("wrong message type {other:?}"),
        };
        let t = roundtrip(ArmAction::Takeoff { altitude_m: 0.35 });
        assert_eq!((t.command, t.param7), (MavCmd::MAV_CMD_NAV_TAKEOFF, 0.35));
        let l = roundtrip(ArmAction::Land);
        assert_eq!(
            (l.command, l.param5, l.param6),
            (MavCmd::MAV_CMD_NAV_LAND, 0.0, 0.0)
        );
        // A disarm that is never forced (param2 21196 would be).
        let d = roundtrip(ArmAction::Disarm);
        assert_eq!(d.command, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM);
        assert_eq!((d.param1, d.param2), (0.0, 0.0));
    }
}
