//! A scenario's `[origin]` as `plan` prints it: the frame, then each primary leader's start
//! and goals both in scenario metres and as WGS-84 latitude, longitude and altitude.

use cdm_math::{vec3, Vec3};
use cdm_model::formation::Role;
use cdm_scenario::{GeoOrigin, Scenario};

/// Nothing without an `[origin]`. Latitude and longitude to 1e-10 degree (about 0.01 mm),
/// altitude to 0.1 mm: far finer than any GPS fix, so that the lines can be checked against a
/// reference implementation (tests/python/check_geodetic.py).
pub fn print_origin(s: &Scenario) {
    let Some(o) = &s.file.geo_origin else {
        return;
    };
    out!(
        "geographic origin: lat {:.10} deg, lon {:.10} deg, alt {:.4} m AMSL, +x heading {} deg (WGS-84, tangent plane)",
        o.lat_deg, o.lon_deg, o.alt_m, o.heading_deg
    );
    let primaries: Vec<_> = s
        .file
        .agents
        .iter()
        .filter(|a| a.role == Role::Primary)
        .collect();
    for a in &primaries {
        line(o, a.id, "start", &vec3(a.position));
        if let Some(g) = a.goal {
            line(o, a.id, "goal 1", &vec3(g));
        }
    }
    // Segments list the primaries' goals in ascending id order.
    let mut ids: Vec<u32> = primaries.iter().map(|a| a.id).collect();
    ids.sort_unstable();
    for (k, seg) in s.file.segments.iter().enumerate() {
        for (id, g) in ids.iter().zip(&seg.goals) {
            line(o, *id, &format!("goal {}", k + 2), &vec3(*g));
        }
    }
}

fn line(o: &GeoOrigin, id: u32, what: &str, p: &Vec3) {
    let g = o.geodetic(p);
    out!(
        "  leader {id:<4} {what:<7} local ({:.4}, {:.4}, {:.4}) m -> lat {:.10} lon {:.10} alt {:.4} m",
        p.x, p.y, p.z, g.lat_deg, g.lon_deg, g.alt_m
    );
}
