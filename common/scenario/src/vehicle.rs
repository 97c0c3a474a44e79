//! `[vehicle]`: what the quadcopters can fly (speeds, accelerations) and how far their downwash
//! reaches below them. The certificate bounds every member's commanded motion against the
//! limits, and separation is proven and audited in the downwash metric
//! (`cdm_model::limits`).

use serde::{Deserialize, Serialize};

use super::ScenarioErrorKind as E;
use crate::fields::positive;
use cdm_math::Real;
use cdm_model::limits::Limit;

/// `[vehicle]`: every key optional; an absent limit is not checked, an absent ratio is 1 (the
/// paper's spheres).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleSpec {
    /// Largest horizontal speed, m/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_speed_xy_m_s: Option<Real>,
    /// Largest climb rate, m/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_speed_up_m_s: Option<Real>,
    /// Largest descent rate, m/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_speed_down_m_s: Option<Real>,
    /// Largest horizontal acceleration, m/s^2.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_accel_xy_m_s2: Option<Real>,
    /// Largest vertical acceleration (either way), m/s^2.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_accel_z_m_s2: Option<Real>,
    /// The downwash ellipsoid's vertical semi-axis over its horizontal one (eps), >= 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub downwash_ratio: Option<Real>,
}

impl VehicleSpec {
    /// The value of one limit, if the file sets it.
    pub fn limit(&self, l: Limit) -> Option<Real> {
        match l {
            Limit::SpeedXy => self.max_speed_xy_m_s,
            Limit::SpeedUp => self.max_speed_up_m_s,
            Limit::SpeedDown => self.max_speed_down_m_s,
            Limit::AccelXy => self.max_accel_xy_m_s2,
            Limit::AccelZ => self.max_accel_z_m_s2,
        }
    }

    /// The limits the file sets, in the file's order.
    pub fn limits(&self) -> Vec<(Limit, Real)> {
        Limit::ALL
            .into_iter()
            .filter_map(|l| self.limit(l).map(|v| (l, v)))
            .collect()
    }
}

/// The table's numbers: every limit finite and > 0, the ratio finite and >= 1.
pub(super) fn check(v: &VehicleSpec) -> Result<(), E> {
    for l in Limit::ALL {
        if let Some(x) = v.limit(l) {
            positive(&format!("vehicle.{}", l.key()), x)?;
        }
    }
    if let Some(r) = v.downwash_ratio {
        positive("vehicle.downwash_ratio", r)?;
        if r < 1.0 {
            return Err(E::Invalid {
                field: "vehicle.downwash_ratio".into(),
                reason: format!(
                    "must be >= 1 (the vertical semi-axis over the horizontal one), got {r}"
                ),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::Scenario;

    /// Each bad value is refused, naming the key.
    #[test]
    fn bad_values_name_the_key() {
        for (table, key) in [
            ("max_speed_xy_m_s = 0.0", "vehicle.max_speed_xy_m_s"),
            ("max_speed_up_m_s = -1.0", "vehicle.max_speed_up_m_s"),
            ("max_speed_down_m_s = nan", "vehicle.max_speed_down_m_s"),
            ("max_accel_xy_m_s2 = inf", "vehicle.max_accel_xy_m_s2"),
            ("max_accel_z_m_s2 = 0.0", "vehicle.max_accel_z_m_s2"),
            ("downwash_ratio = 0.5", "vehicle.downwash_ratio"),
            ("downwash_ratio = nan", "vehicle.downwash_ratio"),
            ("max_speed = 3.0", "max_speed"),
        ] {
            let text = vehicle_last(table);
            let e = Scenario::parse(&text, "f.toml", crate::Checks::Member).unwrap_err();
            let msg = e.to_string();
            assert!(
                msg.contains(key) && msg.starts_with("f.toml"),
                "{table}: {msg}"
            );
        }
        let ok = vehicle_last("max_speed_xy_m_s = 12.0\ndownwash_ratio = 3.0");
        let s = Scenario::parse(&ok, "f.toml", crate::Checks::Member).unwrap();
        let v = s.file.vehicle.unwrap();
        assert_eq!(v.downwash_ratio, Some(3.0));
        assert_eq!(v.limits().len(), 1);
    }

    /// The paper's scenario as TOML with a `[vehicle]` table holding `table` (tables must come
    /// before the `[[agents]]` array of tables).
    fn vehicle_last(table: &str) -> String {
        let text = toml::to_string(&crate::paper40()).unwrap();
        let at = text.find("[[agents]]").unwrap();
        format!("{}[vehicle]\n{table}\n\n{}", &text[..at], &text[at..])
    }
}
