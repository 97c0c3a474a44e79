//! Losing members in flight in one process (`simulate`), with the real `orchestrator` binary:
//!
//! - `simulate --lose` of a follower, a secondary leader and a primary leader: exit 0, every
//!   loss recorded in audit.json with its tick and the followers that switched triangles, the
//!   lost bodies' rows gone from telemetry.csv from that tick (and present before), the
//!   survivors' separation recomputed from telemetry.csv above 2 eps, and the same bytes twice;
//! - `--on-loss stop` keeps the old behaviour: the loss is a fault, exit 3;
//! - bad `--lose` values are refused with exit 2, naming the value;
//! - `plan --losses --json`: the certificate covers every member, and its number for the worst
//!   loss is what `simulate --lose` of that member at the certificate's tick measures.

use integration_tests::support;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use integration_tests::{bin, describe, run, TempDir};
use serde_json::Value;
use support::read_json;

/// A paper40 flight in-process takes about 3 s in release and the certificate ~15 s on a
/// loaded machine; the rest is slack.
const DEADLINE: Duration = integration_tests::deadline::LONG;

fn orchestrator(args: &[&str]) -> Output {
    let mut c = Command::new(bin("orchestrator"));
    c.args(args);
    run(&mut c, DEADLINE)
}

fn simulate(out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["simulate", "--no-figures", "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    orchestrator(&args)
}

/// Telemetry rows: tick -> id -> (position, desired position).
type Rows = BTreeMap<u64, BTreeMap<u32, ([f64; 3], [f64; 3])>>;

fn telemetry(dir: &Path) -> Rows {
    let text = std::fs::read_to_string(dir.join("telemetry.csv")).expect("telemetry.csv");
    let mut rows = Rows::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let n = |i: usize| f[i].parse::<f64>().expect("number");
        rows.entry(f[0].parse().expect("tick")).or_default().insert(
            f[2].parse().expect("id"),
            ([n(4), n(5), n(6)], [n(10), n(11), n(12)]),
        );
    }
    rows
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[test]
fn simulate_loses_a_follower_a_secondary_and_a_primary_and_flies_on() {
    let tmp = TempDir::new();
    // paper40: 1-3 primary, 4-6 secondary, 20 a follower read by 29; dt = 0.01 s.
    let lose = ["--lose", "20@30", "--lose", "5@45.5", "--lose", "1@60"];
    let a = tmp.path().join("a");
    let out = simulate(&a, &lose);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("lost 3 member(s)"), "{stdout}");
    let audit = read_json(&a.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE");
    let losses = audit["losses"].as_array().expect("losses");
    let got: Vec<(u64, u64, &str)> = losses
        .iter()
        .map(|l| {
            (
                l["id"].as_u64().unwrap(),
                l["tick"].as_u64().unwrap(),
                l["role"].as_str().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        got,
        [
            (20, 3001, "follower"),
            (5, 4551, "secondary"),
            (1, 6001, "primary")
        ]
    );
    let mut lost_so_far = Vec::new();
    for l in losses {
        let id = l["id"].as_u64().unwrap();
        lost_so_far.push(id);
        assert_eq!(
            l["last_tick"].as_u64().unwrap() + 1,
            l["tick"].as_u64().unwrap()
        );
        assert_eq!(l["cause"], "scripted");
        let switched = l["retriangulated"].as_array().unwrap();
        // Its readers switch; a follower repaired for an earlier loss may pick again (the
        // repair is a function of the whole lost set). Nobody reads a lost member afterwards.
        let readers = switched.iter().filter(|s| {
            let old: Vec<u64> = serde_json::from_value(s["old"].clone()).unwrap();
            old.contains(&id)
        });
        assert!(readers.count() > 0, "{l}");
        for s in switched {
            let new: Vec<u64> = serde_json::from_value(s["new"].clone()).unwrap();
            assert!(lost_so_far.iter().all(|x| !new.contains(x)), "{s}");
        }
    }
    // The lost bodies leave telemetry (and the audit) from their loss's tick.
    let rows = telemetry(&a);
    let lost_from: BTreeMap<u32, u64> = [(20, 3001), (5, 4551), (1, 6001)].into();
    let eps2 = 2.0 * audit["eps_m"].as_f64().unwrap();
    let mut min_sep = f64::INFINITY;
    for (tick, agents) in &rows {
        for (id, from) in &lost_from {
            assert_eq!(
                agents.contains_key(id),
                tick < from,
                "agent {id} at tick {tick}"
            );
        }
        let pos: Vec<[f64; 3]> = agents.values().map(|v| v.0).collect();
        for i in 0..pos.len() {
            for j in i + 1..pos.len() {
                min_sep = min_sep.min(dist(&pos[i], &pos[j]));
            }
        }
    }
    assert_eq!(rows.len(), 20001);
    assert!(min_sep > eps2, "survivors' separation {min_sep} <= 2 eps");
    assert_eq!(min_sep, audit["min_separation_m"].as_f64().unwrap());
    // Deterministic: the same losses give the same bytes.
    let b = tmp.path().join("b");
    let again = simulate(&b, &lose);
    assert_eq!(again.status.code(), Some(0), "{}", describe(&again));
    let bytes = |d: &Path| std::fs::read(d.join("telemetry.csv")).unwrap();
    assert!(
        bytes(&a) == bytes(&b),
        "telemetry differs between two identical runs"
    );
}

#[test]
fn on_loss_stop_keeps_the_loss_a_fault() {
    let tmp = TempDir::new();
    let out_dir = tmp.path().join("stop");
    let out = simulate(&out_dir, &["--lose", "20@30", "--on-loss", "stop"]);
    assert_eq!(out.status.code(), Some(3), "{}", describe(&out));
    let audit = read_json(&out_dir.join("audit.json"));
    assert_eq!(audit["verdict"], "FAULT");
    assert_eq!(audit["fault"]["kind"], "lost");
    assert_eq!(audit["fault"]["agent"], 20);
    assert!(audit.get("losses").is_none(), "{audit}");
    let rows = telemetry(&out_dir);
    assert_eq!(rows.keys().last(), Some(&3000));
    // Without losses, audit.json has no `losses` field at all (unchanged for old readers).
    let plain = tmp.path().join("plain");
    let out = simulate(&plain, &["--max-ticks", "100"]);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    assert!(read_json(&plain.join("audit.json")).get("losses").is_none());
}

#[test]
fn bad_lose_values_exit_2_naming_them() {
    let tmp = TempDir::new();
    for (k, (value, needle)) in [
        ("99@10", "no agent with id 99"),
        ("20@-1", "--lose 20@-1"),
        ("20@500", "the flight's last tick"),
        ("twenty@3", "expected ID@SECONDS"),
    ]
    .iter()
    .enumerate()
    {
        let dir = tmp.path().join(format!("bad{k}"));
        let out = simulate(&dir, &["--lose", value]);
        assert_eq!(out.status.code(), Some(2), "{value}: {}", describe(&out));
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{value}: {err}");
    }
    let dir = tmp.path().join("twice");
    let out = simulate(&dir, &["--lose", "20@3", "--lose", "20@4"]);
    assert_eq!(out.status.code(), Some(2), "{}", describe(&out));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--lose 20: given twice"));
}

#[test]
fn plan_losses_certifies_every_member_and_matches_simulate() {
    let tmp = TempDir::new();
    let cert_path = tmp.path().join("cert.json");
    let out = orchestrator(&["plan", "--losses", "--json", cert_path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("loss verdict: survives the loss of any single member"),
        "{stdout}"
    );
    let c = read_json(&cert_path);
    assert_eq!(c["verdict"], "SAFE");
    let l = &c["losses"];
    assert_eq!(l["survives_any_single_loss"], true);
    let members = l["members"].as_array().unwrap();
    let ids: BTreeSet<u64> = members.iter().map(|m| m["id"].as_u64().unwrap()).collect();
    assert_eq!(ids, (1..=40).collect());
    assert!(members.iter().all(|m| m["verdict"] == "SAFE"));
    // The worst loss, flown as a run: same lost tick, same repaired followers, same deviation.
    let worst = members
        .iter()
        .max_by(|a, b| {
            let v = |m: &Value| m["max_repaired_deviation_m"].as_f64().unwrap();
            v(a).total_cmp(&v(b))
        })
        .unwrap();
    let id = worst["id"].as_u64().unwrap();
    let last_tick = l["loss_last_tick"].as_u64().unwrap();
    let at = format!("{id}@{}", l["loss_t_s"].as_f64().unwrap());
    let dir = tmp.path().join("worst");
    let out = simulate(&dir, &["--lose", &at]);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    let audit = read_json(&dir.join("audit.json"));
    let loss = &audit["losses"][0];
    assert_eq!(loss["last_tick"].as_u64(), Some(last_tick));
    assert_eq!(loss["retriangulated"], worst["retriangulated"]);
    assert_eq!(loss["degraded"], worst["degraded"]);
    let repaired: BTreeSet<u32> = loss["retriangulated"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x["id"].as_u64().unwrap() as u32)
        .chain(
            loss["degraded"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_u64().unwrap() as u32),
        )
        .collect();
    let mut dev: f64 = 0.0;
    for (tick, agents) in telemetry(&dir) {
        if tick <= last_tick {
            continue;
        }
        for id in &repaired {
            let (r, ht) = agents[id];
            dev = dev.max(dist(&r, &ht));
        }
    }
    let certified = worst["max_repaired_deviation_m"].as_f64().unwrap();
    assert!(
        (dev - certified).abs() < 1e-9,
        "simulate measures {dev}, the certificate says {certified}"
    );
}
