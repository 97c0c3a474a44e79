//! A HEARTBEAT's flight mode, named the way each autopilot names it, for the messages that say
//! which mode a vehicle left for (`takeover.rs`). Pure: numbers in, names out.
//!
//! - PX4 packs its mode into HEARTBEAT.custom_mode as the `px4_custom_mode` union
//!   (PX4-Autopilot `src/modules/commander/px4_custom_mode.h`): bits 16..24 are the main mode
//!   (`PX4_CUSTOM_MAIN_MODE_*`: 1 MANUAL, 2 ALTCTL, 3 POSCTL, 4 AUTO, 5 ACRO, 6 OFFBOARD,
//!   7 STABILIZED, 8 RATTITUDE (retired), 9 SIMPLE (reserved), 10 TERMINATION, 11
//!   ALTITUDE_CRUISE), bits 24..32 the sub mode (`PX4_CUSTOM_SUB_MODE_AUTO_*`: 1 READY,
//!   2 TAKEOFF, 3 LOITER, 4 MISSION, 5 RTL, 6 LAND, 8 FOLLOW_TARGET, 9 PRECLAND, 10
//!   VTOL_TAKEOFF, 11.. EXTERNAL1..8; `PX4_CUSTOM_SUB_MODE_POSCTL_*`: 0 POSCTL, 1 ORBIT, 2
//!   SLOW). QGroundControl shows them as "Position", "Hold" (AUTO.LOITER), "Return"
//!   (AUTO.RTL); the names here are the header's, as MAVSDK and MAVROS print them.
//! - ArduPilot sends the mode number itself (ArduPilot dev docs, "Get and Set FlightMode": "the
//!   vehicle's current flight mode is sent once per second within the HEARTBEAT message's
//!   custom_mode field"; the numbers are Copter's `FLTMODE1` values, `ArduCopter/mode.h`
//!   `Mode::Number`): 0 STABILIZE, 1 ACRO, 2 ALT_HOLD, 3 AUTO, 4 GUIDED, 5 LOITER, 6 RTL,
//!   7 CIRCLE, 9 LAND, 11 DRIFT, 13 SPORT, 14 FLIP, 15 AUTOTUNE, 16 POSHOLD, 17 BRAKE, 18 THROW,
//!   19 AVOID_ADSB, 20 GUIDED_NOGPS, 21 SMART_RTL, 22 FLOWHOLD, 23 FOLLOW, 24 ZIGZAG,
//!   25 SYSTEMID, 26 AUTOROTATE, 27 AUTO_RTL, 28 TURTLE.
//!
//! A number this table does not know is named by its value ("main mode 12", "mode 42"), never
//! refused: the vehicle is lost either way, the name only helps the operator.

use std::fmt;

use crate::arming::{Autopilot, ARDUCOPTER_MODE_GUIDED, PX4_MAIN_MODE_OFFBOARD};

/// A HEARTBEAT's (autopilot, custom_mode), displayed as the autopilot names the mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FlightMode {
    pub autopilot: Autopilot,
    pub custom_mode: u32,
}

impl FlightMode {
    /// Whether this is the mode that flies external position targets: PX4's OFFBOARD (main
    /// mode 6, whatever the sub mode), ArduCopter's GUIDED (4).
    pub fn is_guided(self) -> bool {
        self.autopilot.in_guided_mode(self.custom_mode)
    }

    /// The name of the mode a member flies its vehicle in, for this autopilot.
    pub fn guided_name(autopilot: Autopilot) -> &'static str {
        match autopilot {
            Autopilot::Px4 => "OFFBOARD",
            Autopilot::ArduPilot => "GUIDED",
            Autopilot::Other(_) => "OFFBOARD/GUIDED",
        }
    }

    /// PX4's main and sub mode (bits 16..24 and 24..32 of custom_mode).
    fn px4_parts(self) -> (u32, u32) {
        (
            (self.custom_mode >> 16) & 0xff,
            (self.custom_mode >> 24) & 0xff,
        )
    }
}

fn px4_main_name(main: u32) -> Option<&'static str> {
    Some(match main {
        1 => "MANUAL",
        2 => "ALTCTL",
        3 => "POSCTL",
        4 => "AUTO",
        5 => "ACRO",
        PX4_MAIN_MODE_OFFBOARD => "OFFBOARD",
        7 => "STABILIZED",
        8 => "RATTITUDE",
        9 => "SIMPLE",
        10 => "TERMINATION",
        11 => "ALTITUDE_CRUISE",
        _ => return None,
    })
}

fn px4_auto_sub_name(sub: u32) -> Option<&'static str> {
    Some(match sub {
        1 => "READY",
        2 => "TAKEOFF",
        3 => "LOITER",
        4 => "MISSION",
        5 => "RTL",
        6 => "LAND",
        7 => "RTGS",
        8 => "FOLLOW_TARGET",
        9 => "PRECLAND",
        10 => "VTOL_TAKEOFF",
        _ => return None,
    })
}

fn arducopter_name(mode: u32) -> Option<&'static str> {
    Some(match mode {
        0 => "STABILIZE",
        1 => "ACRO",
        2 => "ALT_HOLD",
        3 => "AUTO",
        ARDUCOPTER_MODE_GUIDED => "GUIDED",
        5 => "LOITER",
        6 => "RTL",
        7 => "CIRCLE",
        9 => "LAND",
        11 => "DRIFT",
        13 => "SPORT",
        14 => "FLIP",
        15 => "AUTOTUNE",
        16 => "POSHOLD",
        17 => "BRAKE",
        18 => "THROW",
        19 => "AVOID_ADSB",
        20 => "GUIDED_NOGPS",
        21 => "SMART_RTL",
        22 => "FLOWHOLD",
        23 => "FOLLOW",
        24 => "ZIGZAG",
        25 => "SYSTEMID",
        26 => "AUTOROTATE",
        27 => "AUTO_RTL",
        28 => "TURTLE",
        _ => return None,
    })
}

impl fmt::Display for FlightMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.autopilot {
            Autopilot::Px4 => {
                let (main, sub) = self.px4_parts();
                match (px4_main_name(main), main) {
                    (Some(name), 4) => match px4_auto_sub_name(sub) {
                        Some(s) => write!(f, "{name}.{s}"),
                        None if (11..=18).contains(&sub) => {
                            write!(f, "{name}.EXTERNAL{}", sub - 10)
                        }
                        None => write!(f, "{name}.sub mode {sub}"),
                    },
                    (Some(name), 3) if sub == 1 => write!(f, "{name}.ORBIT"),
                    (Some(name), 3) if sub == 2 => write!(f, "{name}.SLOW"),
                    (Some(name), _) => f.write_str(name),
                    (None, _) => {
                        write!(f, "main mode {main} (custom_mode {:#x})", self.custom_mode)
                    }
                }
            }
            Autopilot::ArduPilot => match arducopter_name(self.custom_mode) {
                Some(name) => f.write_str(name),
                None => write!(f, "mode {}", self.custom_mode),
            },
            Autopilot::Other(a) => {
                write!(f, "custom_mode {} (MAV_AUTOPILOT {a})", self.custom_mode)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn px4(main: u32, sub: u32) -> FlightMode {
        FlightMode {
            autopilot: Autopilot::Px4,
            custom_mode: (main << 16) | (sub << 24),
        }
    }

    fn copter(mode: u32) -> FlightMode {
        FlightMode {
            autopilot: Autopilot::ArduPilot,
            custom_mode: mode,
        }
    }

    #[test]
    fn px4_modes_are_named_as_its_header_names_them() {
        let cases = [
            (px4(6, 0), "OFFBOARD"),
            (px4(3, 0), "POSCTL"),
            (px4(3, 1), "POSCTL.ORBIT"),
            (px4(2, 0), "ALTCTL"),
            (px4(1, 0), "MANUAL"),
            (px4(4, 3), "AUTO.LOITER"),
            (px4(4, 5), "AUTO.RTL"),
            (px4(4, 6), "AUTO.LAND"),
            (px4(4, 12), "AUTO.EXTERNAL2"),
            (px4(4, 99), "AUTO.sub mode 99"),
            (px4(10, 0), "TERMINATION"),
            (px4(12, 0), "main mode 12 (custom_mode 0xc0000)"),
        ];
        for (mode, name) in cases {
            assert_eq!(mode.to_string(), name, "{mode:?}");
        }
        assert!(px4(6, 0).is_guided());
        assert!(!px4(3, 0).is_guided());
    }

    #[test]
    fn arducopter_modes_are_its_mode_numbers() {
        assert_eq!(copter(4).to_string(), "GUIDED");
        assert_eq!(copter(5).to_string(), "LOITER");
        assert_eq!(copter(6).to_string(), "RTL");
        assert_eq!(copter(9).to_string(), "LAND");
        assert_eq!(copter(0).to_string(), "STABILIZE");
        assert_eq!(copter(8).to_string(), "mode 8");
        assert!(copter(4).is_guided());
        assert!(
            !copter(20).is_guided(),
            "GUIDED_NOGPS flies no position targets"
        );
        let other = FlightMode {
            autopilot: Autopilot::Other(8),
            custom_mode: 3,
        };
        assert_eq!(other.to_string(), "custom_mode 3 (MAV_AUTOPILOT 8)");
    }
}
