//! `orchestrator plan --scenario FILE` refuses every kind of bad scenario with exit code 2 and an
//! `error:` line that names the file and the agent(s) or field at fault, never with a panic.
//!
//! Each test starts from the paper's 40-agent scenario (`paper40`: primary leaders 1-3,
//! secondary leaders 4-6, followers 7-40) and breaks one thing, or writes raw TOML for parse
//! errors. The expected phrases are those of `cdm_core::scenario` (`mod.rs`, `validate.rs`) and
//! `cdm_core::formation`.

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use cdm_core::formation::Role;
use cdm_core::scenario::{AgentSpec, ScenarioFile};
use integration_tests::{
    bin, describe, paper40, run, scenario_toml, write_scenario, write_text, TempDir,
};

/// A bad file is refused in milliseconds; the deadline only keeps a hang from stalling the suite.
const REFUSE_DEADLINE: Duration = integration_tests::deadline::SHORT;
/// A valid file is planned in full (a few seconds to tens of seconds in release).
const PLAN_DEADLINE: Duration = integration_tests::deadline::FLIGHT;

type V3 = [f64; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn scale(a: V3, k: f64) -> V3 {
    [a[0] * k, a[1] * k, a[2] * k]
}

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn unit(a: V3) -> V3 {
    scale(a, 1.0 / dot(a, a).sqrt())
}

/// The agent with this id.
fn agent(f: &mut ScenarioFile, id: u32) -> &mut AgentSpec {
    f.agents
        .iter_mut()
        .find(|a| a.id == id)
        .unwrap_or_else(|| panic!("scenario `{}` has no agent {id}", f.name))
}

/// Positions of the three primary leaders, in file order.
fn primaries(f: &ScenarioFile) -> [V3; 3] {
    let p: Vec<V3> = f
        .agents
        .iter()
        .filter(|a| a.role == Role::Primary)
        .map(|a| a.position)
        .collect();
    assert_eq!(p.len(), 3, "paper40 must have 3 primary leaders");
    [p[0], p[1], p[2]]
}

/// Unit normal of the primary leaders' plane.
fn plane_normal(f: &ScenarioFile) -> V3 {
    let [r1, r2, r3] = primaries(f);
    unit(cross(sub(r2, r1), sub(r3, r1)))
}

/// Centroid of the primary leaders (on their plane, inside every leader's hull).
fn primary_centroid(f: &ScenarioFile) -> V3 {
    let [r1, r2, r3] = primaries(f);
    scale(add(add(r1, r2), r3), 1.0 / 3.0)
}

/// Barycentric weights of `p` in the triangle `t`, measured in the plane with normal `n`.
fn weights(p: V3, t: [V3; 3], n: V3) -> V3 {
    let area = |a: V3, b: V3, c: V3| dot(cross(sub(b, a), sub(c, a)), n);
    let total = area(t[0], t[1], t[2]);
    [
        area(p, t[1], t[2]) / total,
        area(t[0], p, t[2]) / total,
        area(t[0], t[1], p) / total,
    ]
}

/// Run `orchestrator plan --scenario path`. `RUST_LOG` is cleared so that the notes the tool
/// logs at its default level (projections) appear whatever the caller's environment says.
fn plan(path: &Path, deadline: Duration) -> Output {
    run(
        Command::new(bin("orchestrator"))
            .arg("plan")
            .arg("--scenario")
            .arg(path)
            .env_remove("RUST_LOG"),
        deadline,
    )
}

/// `orchestrator plan` must refuse `path` with exit code 2, no panic, and an `error:` line
/// naming the file; that line (with any continuation lines, as a TOML parse error has) must
/// contain every phrase in `expected`.
fn assert_refused(path: &Path, expected: &[&str]) {
    let out = plan(path, REFUSE_DEADLINE);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.contains("panicked"),
        "orchestrator panicked on {}:\n{}",
        path.display(),
        describe(&out)
    );
    assert_eq!(
        out.status.code(),
        Some(2),
        "exit code for bad input {} must be 2:\n{}",
        path.display(),
        describe(&out)
    );
    let origin = format!("{}: ", path.display());
    let start = stderr
        .lines()
        .position(|l| l.starts_with("error:") && l.contains(&origin))
        .unwrap_or_else(|| {
            panic!(
                "no stderr line starts with `error:` and names {:?}:\n{}",
                origin,
                describe(&out)
            )
        });
    let message: Vec<&str> = stderr.lines().skip(start).collect();
    let message = message.join("\n");
    for phrase in expected {
        assert!(
            message.contains(phrase),
            "the error for {} does not contain {phrase:?}:\n{}",
            path.display(),
            describe(&out)
        );
    }
}

/// Write `file` as `name` in a fresh directory and assert `plan` refuses it with `expected`.
fn assert_scenario_refused(name: &str, file: &ScenarioFile, expected: &[&str]) {
    let dir = TempDir::new();
    let path = write_scenario(dir.path(), name, file);
    assert_refused(&path, expected);
}

/// The 1-based number of the first line of `text` that starts with `prefix`.
fn line_of(text: &str, prefix: &str) -> usize {
    text.lines()
        .position(|l| l.starts_with(prefix))
        .map(|k| k + 1)
        .unwrap_or_else(|| panic!("no line starts with {prefix:?}:\n{text}"))
}

/// paper40's TOML as a table, for edits the typed file cannot express (unknown keys).
fn paper40_table() -> toml::Table {
    toml::from_str(&scenario_toml(&paper40()))
        .unwrap_or_else(|e| panic!("paper40 does not round-trip through TOML: {e}"))
}

// ---- the file itself -------------------------------------------------------------------------

#[test]
fn nonexistent_file_is_refused() {
    let dir = TempDir::new();
    let path = dir.path().join("does-not-exist.toml");
    assert_refused(&path, &["cannot read the file"]);
}

#[test]
fn directory_instead_of_file_is_refused() {
    let dir = TempDir::new();
    assert_refused(dir.path(), &["cannot read the file"]);
}

#[test]
fn malformed_toml_is_refused() {
    let dir = TempDir::new();
    let path = write_text(
        dir.path(),
        "malformed.toml",
        "name = \"broken\"\nt_total_s = 200.0\neps_m = [1.5\n",
    );
    assert_refused(&path, &["malformed scenario", "line 3"]);
}

#[test]
fn unknown_top_level_key_is_refused() {
    let mut table = paper40_table();
    table.insert("colour".into(), toml::Value::String("red".into()));
    let dir = TempDir::new();
    let text = toml::to_string(&table).unwrap_or_else(|e| panic!("serialising: {e}"));
    let path = write_text(dir.path(), "unknown-top.toml", &text);
    let at = format!("line {},", line_of(&text, "colour ="));
    assert_refused(
        &path,
        &["malformed scenario", &at, "unknown field `colour`"],
    );
}

#[test]
fn unknown_key_in_agent_is_refused() {
    let mut table = paper40_table();
    let agents = table
        .get_mut("agents")
        .and_then(toml::Value::as_array_mut)
        .unwrap_or_else(|| panic!("paper40's TOML has no [[agents]] array"));
    let seventh = agents
        .get_mut(6)
        .and_then(toml::Value::as_table_mut)
        .unwrap_or_else(|| panic!("paper40's 7th agent is not a table"));
    seventh.insert("speed_mps".into(), toml::Value::Float(3.0));
    let dir = TempDir::new();
    let text = toml::to_string(&table).unwrap_or_else(|e| panic!("serialising: {e}"));
    let path = write_text(dir.path(), "unknown-agent.toml", &text);
    // The parse error locates the key by line: the line inside agent 7's table.
    let line = line_of(&text, "speed_mps =");
    let table_id = text
        .lines()
        .take(line)
        .filter(|l| l.starts_with("id = "))
        .last()
        .unwrap_or_else(|| panic!("no `id = ` line before the unknown key:\n{text}"));
    assert_eq!(
        table_id, "id = 7",
        "the unknown key must be in agent 7's table"
    );
    let at = format!("line {line},");
    assert_refused(
        &path,
        &["malformed scenario", &at, "unknown field `speed_mps`"],
    );
}

// ---- numbers ---------------------------------------------------------------------------------

#[test]
fn nan_in_a_position_is_refused() {
    let mut f = paper40();
    agent(&mut f, 7).position[2] = f64::NAN;
    let text = scenario_toml(&f);
    assert!(text.contains("nan"), "the file must hold a TOML `nan`");
    assert_scenario_refused(
        "nan-position.toml",
        &f,
        &["field `agents[id=7].position[2]` must be a finite number, got NaN"],
    );
}

#[test]
fn infinite_t_total_is_refused() {
    let mut f = paper40();
    f.t_total_s = f64::INFINITY;
    let text = scenario_toml(&f);
    assert!(text.contains("inf"), "the file must hold a TOML `inf`");
    assert_scenario_refused(
        "inf-t-total.toml",
        &f,
        &["field `t_total_s` must be a finite number, got inf"],
    );
}

#[test]
fn zero_t_total_is_refused() {
    let mut f = paper40();
    f.t_total_s = 0.0;
    assert_scenario_refused(
        "zero-t-total.toml",
        &f,
        &["field `t_total_s` must be > 0, got 0"],
    );
}

#[test]
fn negative_t_total_is_refused() {
    let mut f = paper40();
    f.t_total_s = -5.0;
    assert_scenario_refused(
        "negative-t-total.toml",
        &f,
        &["field `t_total_s` must be > 0, got -5"],
    );
}

#[test]
fn non_positive_comm_hz_is_refused() {
    let mut f = paper40();
    f.comm_hz = -10.0;
    assert_scenario_refused(
        "negative-comm-hz.toml",
        &f,
        &["field `comm_hz` must be > 0, got -10"],
    );
    f.comm_hz = 0.0;
    assert_scenario_refused(
        "zero-comm-hz.toml",
        &f,
        &["field `comm_hz` must be > 0, got 0"],
    );
}

#[test]
fn lambda_cd_min_and_delta_together_are_refused() {
    let mut f = paper40();
    f.lambda_cd_min = Some(0.5);
    f.delta_m = Some(2.0);
    assert_scenario_refused(
        "lambda-and-delta.toml",
        &f,
        &["field `lambda_cd_min`", "`delta_m` are exclusive"],
    );
}

#[test]
fn unstable_gains_are_refused() {
    let mut f = paper40();
    f.gains = [1.0, 1.0, 10.0, 1.0];
    assert_scenario_refused(
        "unstable-gains.toml",
        &f,
        &["gains [1.0, 1.0, 10.0, 1.0] are unstable"],
    );
}

// ---- ids and roles ---------------------------------------------------------------------------

#[test]
fn duplicate_id_is_refused() {
    let mut f = paper40();
    agent(&mut f, 12).id = 7;
    assert_scenario_refused(
        "duplicate-id.toml",
        &f,
        &["agent id 7 appears more than once"],
    );
}

#[test]
fn two_primary_leaders_are_refused() {
    let mut f = paper40();
    let a = agent(&mut f, 3);
    a.role = Role::Secondary;
    a.goal = None;
    assert_scenario_refused(
        "two-primaries.toml",
        &f,
        &["exactly 3 primary leaders, found [1, 2]"],
    );
}

#[test]
fn four_primary_leaders_are_refused() {
    let mut f = paper40();
    let a = agent(&mut f, 4);
    a.role = Role::Primary;
    a.goal = Some([0.0, 0.0, 560.0]);
    assert_scenario_refused(
        "four-primaries.toml",
        &f,
        &["exactly 3 primary leaders, found [1, 2, 3, 4]"],
    );
}

#[test]
fn primary_without_goal_is_refused() {
    let mut f = paper40();
    agent(&mut f, 2).goal = None;
    assert_scenario_refused(
        "missing-goal.toml",
        &f,
        &["primary leader 2: `goal` is missing"],
    );
}

#[test]
fn goal_on_secondary_leader_is_refused() {
    let mut f = paper40();
    agent(&mut f, 5).goal = Some([0.0, 0.0, 560.0]);
    assert_scenario_refused(
        "goal-on-secondary.toml",
        &f,
        &["agent 5 (secondary): only primary leaders have a `goal`"],
    );
}

#[test]
fn goal_on_follower_is_refused() {
    let mut f = paper40();
    agent(&mut f, 9).goal = Some([0.0, 0.0, 560.0]);
    assert_scenario_refused(
        "goal-on-follower.toml",
        &f,
        &["agent 9 (follower): only primary leaders have a `goal`"],
    );
}

#[test]
fn in_neighbors_on_primary_leader_are_refused() {
    let mut f = paper40();
    agent(&mut f, 1).in_neighbors = Some(vec![4, 5, 6]);
    assert_scenario_refused(
        "neighbors-on-primary.toml",
        &f,
        &["agent 1 (primary): only followers have `in_neighbors`"],
    );
}

#[test]
fn in_neighbors_on_secondary_leader_are_refused() {
    let mut f = paper40();
    agent(&mut f, 6).in_neighbors = Some(vec![1, 2, 3]);
    assert_scenario_refused(
        "neighbors-on-secondary.toml",
        &f,
        &["agent 6 (secondary): only followers have `in_neighbors`"],
    );
}

// ---- geometry of the leaders -----------------------------------------------------------------

#[test]
fn collinear_primaries_at_t0_are_refused() {
    let mut f = paper40();
    let [r1, r2, _] = primaries(&f);
    // Leader 3 half-way between leaders 1 and 2.
    agent(&mut f, 3).position = scale(add(r1, r2), 0.5);
    assert_scenario_refused(
        "collinear-t0.toml",
        &f,
        &["primary leaders [1, 2, 3] are (nearly) collinear at t0"],
    );
}

#[test]
fn primaries_collinear_during_the_plan_are_refused() {
    let mut f = paper40();
    let [r1, r2, r3] = primaries(&f);
    // The goal triangle is the start triangle mirrored across the line through leaders 1 and 2
    // (in their plane), then translated: both ends are proper triangles, but on the straight
    // path leader 3 crosses that line half-way, so the triangle flips through a segment.
    let u = unit(sub(r2, r1));
    let p = sub(r3, r1);
    let mirrored_r3 = add(r1, sub(scale(u, 2.0 * dot(p, u)), p));
    let shift = [0.0, 0.0, -300.0];
    agent(&mut f, 1).goal = Some(add(r1, shift));
    agent(&mut f, 2).goal = Some(add(r2, shift));
    agent(&mut f, 3).goal = Some(add(mirrored_r3, shift));
    let dir = TempDir::new();
    let path = write_scenario(dir.path(), "collinear-mid-plan.toml", &f);
    assert_refused(
        &path,
        &["primary leaders [1, 2, 3] are (nearly) collinear at t = "],
    );
    // Neither end is the problem.
    let out = plan(&path, REFUSE_DEADLINE);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.contains("at t0") && !stderr.contains("at their goals"),
        "the degenerate triangle is mid-plan, not at an end:\n{}",
        describe(&out)
    );
}

#[test]
fn non_convex_leading_polygon_is_refused() {
    let mut f = paper40();
    // Secondary leader 5 at the primaries' centroid: inside the hull, not a vertex.
    agent(&mut f, 5).position = primary_centroid(&f);
    assert_scenario_refused(
        "non-convex.toml",
        &f,
        &["leader 5: the leading polygon is not strictly convex"],
    );
}

// ---- followers and the plane -----------------------------------------------------------------

#[test]
fn follower_outside_the_leading_polygon_is_refused() {
    let mut f = paper40();
    let c = primary_centroid(&f);
    let [r1, _, _] = primaries(&f);
    // On the plane, beyond leader 1 as seen from the centroid: outside every leader's hull.
    agent(&mut f, 7).position = add(r1, sub(r1, c));
    assert_scenario_refused(
        "outside-polygon.toml",
        &f,
        &["agent 7: outside the leading polygon"],
    );
}

#[test]
fn agent_far_off_the_plane_is_refused() {
    let mut f = paper40();
    let n = plane_normal(&f);
    let a = agent(&mut f, 7);
    a.position = add(a.position, scale(n, 5.0));
    assert_scenario_refused(
        "off-plane.toml",
        &f,
        &["agent 7: 5.000 m off the primary leaders' plane (tolerance 1 m"],
    );
}

#[test]
fn agent_near_the_plane_is_projected() {
    let mut f = paper40();
    let n = plane_normal(&f);
    let a = agent(&mut f, 7);
    a.position = add(a.position, scale(n, 0.5));
    let dir = TempDir::new();
    let path = write_scenario(dir.path(), "near-plane.toml", &f);
    let out = plan(&path, PLAN_DEADLINE);
    let all = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        !all.contains("panicked"),
        "orchestrator panicked:\n{}",
        describe(&out)
    );
    assert!(
        matches!(out.status.code(), Some(0 | 1)),
        "a scenario within the plane tolerance must be planned (exit 0 or 1):\n{}",
        describe(&out)
    );
    assert!(
        all.contains("agent 7: projected 0.500 m"),
        "the output must say agent 7 was projected onto the plane:\n{}",
        describe(&out)
    );
}

// ---- in-neighbours ---------------------------------------------------------------------------

#[test]
fn follower_outside_its_neighbors_triangle_is_refused() {
    let mut f = paper40();
    let n = plane_normal(&f);
    let leaders: Vec<(u32, V3)> = f
        .agents
        .iter()
        .filter(|a| a.role != Role::Follower)
        .map(|a| (a.id, a.position))
        .collect();
    // Follower 7 with three leaders whose triangle clearly leaves it out (the leaders are the
    // vertices of a strictly convex polygon, so any three of them make a proper triangle).
    let p = agent(&mut f, 7).position;
    let mut chosen = None;
    'search: for i in 0..leaders.len() {
        for j in i + 1..leaders.len() {
            for k in j + 1..leaders.len() {
                let t = [leaders[i].1, leaders[j].1, leaders[k].1];
                if weights(p, t, n).iter().any(|w| *w < -0.05) {
                    chosen = Some([leaders[i].0, leaders[j].0, leaders[k].0]);
                    break 'search;
                }
            }
        }
    }
    let chosen = chosen.unwrap_or_else(|| panic!("no leader triangle leaves follower 7 out"));
    agent(&mut f, 7).in_neighbors = Some(chosen.to_vec());
    let expected = format!(
        "agent 7: not strictly inside the triangle of its in-neighbours {:?}",
        chosen
    );
    assert_scenario_refused("outside-triangle.toml", &f, &[&expected]);
}

#[test]
fn unknown_in_neighbor_is_refused() {
    let mut f = paper40();
    agent(&mut f, 7).in_neighbors = Some(vec![1, 2, 999]);
    assert_scenario_refused(
        "unknown-neighbor.toml",
        &f,
        &["agent 7: in-neighbour 999 does not exist"],
    );
}

#[test]
fn follower_listing_itself_is_refused() {
    let mut f = paper40();
    agent(&mut f, 7).in_neighbors = Some(vec![1, 7, 2]);
    assert_scenario_refused(
        "self-neighbor.toml",
        &f,
        &["agent 7: lists itself as an in-neighbour"],
    );
}

#[test]
fn two_in_neighbors_are_refused() {
    let mut f = paper40();
    agent(&mut f, 7).in_neighbors = Some(vec![1, 2]);
    assert_scenario_refused(
        "two-neighbors.toml",
        &f,
        &["agent 7: in-neighbours must be 3 distinct agents, got [1, 2]"],
    );
}
