//! Property tests of the scenario parser, the validator and graph synthesis (bad input):
//!
//! - Random edits of paper40's TOML text and random structured scenarios never panic or hang;
//!   every rejection names where the problem is (a line of the file, a field or an agent).
//! - Random valid formations (followers anywhere inside the leading polygon, 4 to 500 agents,
//!   many seeds): graph synthesis either gives every follower three in-neighbours with weights
//!   at or above the floor, summing to one and reaching it from the leaders, or a clear error
//!   naming the follower. Never a silent bad graph.
//!
//! Case counts keep the file to a few seconds in release; a watchdog ends the process if a test
//! hangs. How to run: `cargo test --release -p cdm-scenario --test proptest`.

use cdm_test_support::Watchdog;

use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

use cdm_model::formation::Role;
use cdm_scenario::{generated, paper40, AgentSpec, Checks, Scenario, ScenarioFile};
use proptest::prelude::*;
use proptest::sample::Index;

/// No case should take more than a fraction of a second; this only stops a hang.
const DEADLINE: Duration = Duration::from_secs(60);

/// Whether a rejection says where the problem is: a line of the file (TOML errors), a field, an
/// agent, a follower or the leaders, or the gains.
fn names_the_place(msg: &str) -> bool {
    ["line ", "field `", "agent", "follower ", "leader", "gains"]
        .iter()
        .any(|n| msg.contains(n))
}

fn check_outcome(result: Result<Scenario, cdm_scenario::ScenarioError>) -> Result<(), String> {
    match result {
        Ok(s) => check_graph(&s),
        Err(e) => {
            let msg = e.to_string();
            if !msg.starts_with("case.toml: ") {
                return Err(format!("the rejection does not name the file: {msg}"));
            }
            if !names_the_place(&msg) {
                return Err(format!(
                    "the rejection names no line, field or agent: {msg}"
                ));
            }
            Ok(())
        }
    }
}

/// The graph of an accepted scenario: every follower has three distinct in-neighbours of the
/// team, weights >= the floor (synthesised links) or > 0 (given links), summing to one, and
/// every follower is reached from the leaders.
fn check_graph(s: &Scenario) -> Result<(), String> {
    let floor = s
        .file
        .weight_floor
        .unwrap_or(cdm_model::graph::DEFAULT_WEIGHT_FLOOR);
    let given: BTreeSet<u32> = s
        .file
        .agents
        .iter()
        .filter(|a| a.in_neighbors.is_some())
        .map(|a| a.id)
        .collect();
    let ids: BTreeSet<u32> = s.formation.members.iter().map(|m| m.id).collect();
    let mut reads: BTreeMap<u32, [u32; 3]> = BTreeMap::new();
    for m in &s.formation.members {
        match (m.role, &m.link) {
            (Role::Follower, Some(l)) => {
                let distinct: BTreeSet<u32> = l.in_neighbors.iter().copied().collect();
                if distinct.len() != 3 || !distinct.is_subset(&ids) || distinct.contains(&m.id) {
                    return Err(format!(
                        "follower {}: in-neighbours {:?}",
                        m.id, l.in_neighbors
                    ));
                }
                let min = if given.contains(&m.id) { 0.0 } else { floor };
                let sum: f64 = l.weights.iter().sum();
                if l.weights.iter().any(|w| !(*w >= min && *w > 0.0)) || (sum - 1.0).abs() > 1e-9 {
                    return Err(format!(
                        "follower {}: weights {:?} (floor {floor}, sum {sum})",
                        m.id, l.weights
                    ));
                }
                reads.insert(m.id, l.in_neighbors);
            }
            (Role::Follower, None) => return Err(format!("follower {} has no link", m.id)),
            (_, Some(_)) => return Err(format!("leader {} has a link", m.id)),
            (_, None) => {}
        }
    }
    // Reachability (Assumption 2): grow the set of reached agents from the leaders.
    let mut reached: BTreeSet<u32> = s
        .formation
        .members
        .iter()
        .filter(|m| m.role.is_leader())
        .map(|m| m.id)
        .collect();
    loop {
        let before = reached.len();
        for (&f, ins) in &reads {
            if ins.iter().any(|j| reached.contains(j)) {
                reached.insert(f);
            }
        }
        if reached.len() == before {
            break;
        }
    }
    let unreached: Vec<u32> = reads
        .keys()
        .filter(|f| !reached.contains(f))
        .copied()
        .collect();
    if unreached.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "followers {unreached:?} are not reached from the leaders"
        ))
    }
}

/// Text fragments an edit may insert: numbers a float field should not take, TOML punctuation,
/// keys (known and unknown), whole tables.
const FRAGMENTS: &[&str] = &[
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "1e400",
    "1e-400",
    "4294967296",
    "-0.0",
    "\"x\"",
    "[",
    "]",
    "=",
    ",",
    "\"",
    "\n",
    "#",
    "[[agents]]\n",
    "\n[[agents]]\nid = 1\nrole = \"primary\"\nposition = [0.0, 0.0, 0.0]\n",
    "\nid = 7\n",
    "role = \"leader\"",
    "role = \"follower\"",
    "goal = [1.0, 2.0, 3.0]",
    "in_neighbors = [1, 2, 3]",
    "in_neighbors = [7, 7, 7]",
    "in_neighbors = []",
    "bogus = 1",
    "weight_floor = 0.9",
    "plane_tolerance_m = -1.0",
    "substeps = 0",
    "substeps = 100000",
    "delta_m = 1.0",
    "lambda_cd_min = 0.0",
    "t_total_s = 1e300",
    "comm_hz = 1e300",
    "comm_hz = 1e-300",
    "eps_m = 1e9",
    "position = [1e308, 1e308, 1e308]",
    "id = 4294967295",
];

/// One edit of a text: delete a span, insert a fragment, or replace a line with a fragment.
#[derive(Debug, Clone)]
enum Edit {
    Delete(Index, usize),
    Insert(Index, usize),
    ReplaceLine(Index, usize),
    DuplicateLine(Index),
}

fn edit() -> impl Strategy<Value = Edit> {
    let frag = 0..FRAGMENTS.len();
    prop_oneof![
        (any::<Index>(), 1usize..40).prop_map(|(i, n)| Edit::Delete(i, n)),
        (any::<Index>(), frag.clone()).prop_map(|(i, f)| Edit::Insert(i, f)),
        (any::<Index>(), frag).prop_map(|(i, f)| Edit::ReplaceLine(i, f)),
        any::<Index>().prop_map(Edit::DuplicateLine),
    ]
}

/// Applies an edit at a character boundary.
fn apply(text: &str, e: &Edit) -> String {
    let chars: Vec<char> = text.chars().collect();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    match e {
        Edit::Delete(i, n) => {
            let at = i.index(chars.len().max(1)).min(chars.len());
            let end = (at + n).min(chars.len());
            chars[..at].iter().chain(&chars[end..]).collect()
        }
        Edit::Insert(i, f) => {
            let at = i.index(chars.len().max(1)).min(chars.len());
            let mut s: String = chars[..at].iter().collect();
            s.push_str(FRAGMENTS[*f]);
            s.extend(&chars[at..]);
            s
        }
        Edit::ReplaceLine(i, f) => {
            if !lines.is_empty() {
                let k = i.index(lines.len());
                lines[k] = FRAGMENTS[*f].to_string();
            }
            lines.join("\n") + "\n"
        }
        Edit::DuplicateLine(i) => {
            if !lines.is_empty() {
                let k = i.index(lines.len());
                let l = lines[k].clone();
                lines.insert(k, l);
            }
            lines.join("\n") + "\n"
        }
    }
}

/// `cases` random cases, no failure files written next to the sources (a failure prints its
/// minimal case).
fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases,
        max_shrink_iters: 500,
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

fn paper40_text() -> &'static str {
    static TEXT: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    TEXT.get_or_init(|| toml::to_string(&paper40()).expect("paper40 serialises"))
}

proptest! {
    #![proptest_config(config(500))]

    /// Random edits of paper40's text: parsed and validated without panic; rejected with the
    /// place named, or accepted with a sound graph.
    #[test]
    fn edited_paper40_text_is_accepted_soundly_or_refused_clearly(
        edits in prop::collection::vec(edit(), 1..4)
    ) {
        let _dog = Watchdog::new("edited paper40 text", DEADLINE);
        let mut text = paper40_text().to_string();
        for e in &edits {
            text = apply(&text, e);
        }
        let outcome = Scenario::parse(&text, "case.toml", Checks::Member);
        if let Err(why) = check_outcome(outcome) {
            prop_assert!(false, "{why}\n--- text ---\n{text}");
        }
    }
}

fn number() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -10.0f64..400.0,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(-0.0),
        1 => Just(1e300),
        1 => Just(1e-300),
    ]
}

fn agent() -> impl Strategy<Value = AgentSpec> {
    let role = prop_oneof![
        Just(Role::Primary),
        Just(Role::Secondary),
        Just(Role::Follower)
    ];
    let pos = [number(), number(), number()];
    (
        0u32..12,
        role,
        pos,
        prop::option::of([number(), number(), number()]),
        prop::option::of(prop::collection::vec(0u32..12, 0..5)),
    )
        .prop_map(|(id, role, position, goal, in_neighbors)| AgentSpec {
            id,
            role,
            position,
            goal,
            in_neighbors,
        })
}

proptest! {
    #![proptest_config(config(500))]

    /// Random structured scenarios (any numbers, ids, roles, goals and neighbour lists, and
    /// random changes to paper40's agents): never a panic; rejections name the place; an
    /// accepted one has a sound graph.
    #[test]
    fn random_structured_scenarios_are_accepted_soundly_or_refused_clearly(
        t_total_s in number(), eps_m in number(), comm_hz in number(),
        gains in [number(), number(), number(), number()],
        floor in prop::option::of(number()), tolerance in prop::option::of(number()),
        substeps in prop::option::of(0u32..64),
        own in prop::collection::vec(agent(), 0..10),
        from_paper in any::<bool>(), pick in any::<Index>(), replace in agent(),
    ) {
        let _dog = Watchdog::new("random structured scenarios", DEADLINE);
        let file = if from_paper {
            // paper40 with one agent replaced by a random one: mostly near-valid files.
            let mut f = paper40();
            let k = pick.index(f.agents.len());
            f.agents[k] = replace;
            f
        } else {
            ScenarioFile {
                name: "random".into(),
                t_total_s,
                eps_m,
                comm_hz,
                gains,
                lambda_cd_min: None,
                delta_m: None,
                substeps,
                weight_floor: floor,
                plane_tolerance_m: tolerance,
                link: None,
                geo_origin: None,
                takeoff: None,
                segments: Vec::new(),
                landing: None,
                geofence: None,
                obstacles: Vec::new(),
                vehicle: None,
                agents: own,
            }
        };
        let outcome = Scenario::from_file(file.clone(), "case.toml", Checks::Full);
        if let Err(why) = check_outcome(outcome) {
            prop_assert!(false, "{why}\n--- scenario ---\n{file:#?}");
        }
    }
}

/// A small deterministic generator (xorshift64*), so the formation sweep below is the same on
/// every run and can count how many cases were accepted.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Random valid formations: the leaders of `generated(n)`, followers at random convex
/// combinations of the leaders (inside the leading polygon, on its plane). Sizes from 4 to 500,
/// 48 seeds. Each is accepted with a sound graph or refused by name; most are accepted (the
/// sweep is not vacuous).
#[test]
fn random_formations_get_a_sound_graph_or_a_clear_error() {
    let _dog = Watchdog::new("random formations", DEADLINE);
    let mut sizes: Vec<usize> = vec![4, 5, 9, 10, 11, 40, 100, 250, 500];
    let mut rng = Rng(0x5eed_cafe_f00d_d00d);
    while sizes.len() < 48 {
        // Mostly small teams (cheap), some large.
        let n = if rng.unit() < 0.8 {
            4 + (rng.next() % 60) as usize
        } else {
            4 + (rng.next() % 497) as usize
        };
        sizes.push(n);
    }
    let (mut accepted, mut refused) = (0, Vec::new());
    for (seed, &n) in sizes.iter().enumerate() {
        let mut f = generated(n).expect("4 <= n <= 500");
        let leaders: Vec<[f64; 3]> = f
            .agents
            .iter()
            .filter(|a| a.role.is_leader())
            .map(|a| a.position)
            .collect();
        for a in f.agents.iter_mut().filter(|a| a.role == Role::Follower) {
            // A random point of the polygon: convex weights, sharpened so some points lie near
            // the boundary (where synthesis may legitimately fail with a clear error).
            let w: Vec<f64> = leaders.iter().map(|_| rng.unit().powi(3) + 1e-3).collect();
            let sum: f64 = w.iter().sum();
            let mut p = [0.0; 3];
            for (l, wk) in leaders.iter().zip(&w) {
                for d in 0..3 {
                    p[d] += l[d] * wk / sum;
                }
            }
            a.position = p;
        }
        let outcome = Scenario::from_file(f, "case.toml", Checks::Member);
        match &outcome {
            Ok(_) => accepted += 1,
            Err(e) => refused.push(format!("seed {seed}, n {n}: {e}")),
        }
        if let Err(why) = check_outcome(outcome) {
            panic!("seed {seed}, n {n}: {why}");
        }
    }
    println!(
        "{accepted} of {} random formations accepted; refusals:\n{}",
        sizes.len(),
        refused.join("\n")
    );
    assert!(
        accepted * 2 >= sizes.len(),
        "only {accepted} of {} accepted:\n{}",
        sizes.len(),
        refused.join("\n")
    );
}
