//! The live view of a launch (`launch --serve ADDR`): fed by the launch loop's per-tick audit,
//! it sends at most [`FRAMES_PER_S`] frames a second, so the team is not slowed (BENCHMARKS.md).
//! Wall time only paces the frames; it never touches the simulation.

use std::sync::Arc;
use std::time::{Duration, Instant};

use cdm_math::Vec3;
use cdm_records::audit::{AuditReport, CommandSummary, SafetyNumbers};
use cdm_scenario::Scenario;

use super::scene::{CommandMark, Scene, ShownTickMaker};
use super::serve::{serve_page, Hub, ServeError, Server};
use cdm_report::data::TickPositions;

/// Frames sent per second of wall time (the rest of the ticks are skipped).
pub const FRAMES_PER_S: u32 = 10;

/// A live view: the server, and the state of the decimation.
pub struct LiveView {
    hub: Arc<Hub>,
    server: Server,
    scenario: Scenario,
    maker: ShownTickMaker,
    interval: Duration,
    last_sent: Option<(Instant, u64)>,
    /// The commands known so far (from a command file, or told as they are decided): each
    /// frame carries those switched by its tick.
    commands: Vec<CommandMark>,
}

impl LiveView {
    /// Starts serving the live page of `scenario` on `addr`.
    pub fn start(addr: &str, scenario: &Scenario, n: &SafetyNumbers) -> Result<Self, ServeError> {
        let scene = Scene::new(scenario, n.delta_m, n.eps_m, n.lambda_cd_min);
        let hub = Arc::new(Hub::default());
        hub.set_scene(serde_json::to_string(&scene).unwrap_or_else(|_| "null".into()));
        let server = serve_page(addr, super::page(None), Some(hub.clone()))?;
        Ok(LiveView {
            hub,
            server,
            scenario: scenario.clone(),
            maker: ShownTickMaker::new(scenario, n.delta_m + n.eps_m),
            interval: Duration::from_secs(1) / FRAMES_PER_S,
            last_sent: None,
            commands: Vec::new(),
        })
    }

    /// A command decided (accepted or refused): the page marks it from its switch tick on, as
    /// it shows a loss from the loss's tick.
    pub fn command(&mut self, c: &CommandSummary) {
        self.commands.push(CommandMark::from(c));
    }

    /// The address the page is served on.
    pub fn addr(&self) -> &str {
        &self.server.addr
    }

    /// One audited tick: sent when the last frame is at least an interval old (the first and
    /// the last tick always are). `flying(k)` is false for a member lost by this tick.
    pub fn tick(
        &mut self,
        tick: u64,
        t: f64,
        (pos, ht): (&[Vec3], &[Vec3]),
        flying: impl Fn(usize) -> bool,
        report: &AuditReport,
    ) {
        let now = Instant::now();
        let due = self
            .last_sent
            .is_none_or(|(at, _)| now.duration_since(at) >= self.interval);
        if !due && tick != self.scenario.last_tick() {
            return;
        }
        let alive: Vec<bool> = (0..pos.len()).map(flying).collect();
        let tp = TickPositions {
            tick,
            t_s: t,
            pos,
            ht,
            alive: &alive,
        };
        let mut frame = self.maker.frame(&self.scenario, &tp);
        if let Some((at, k)) = self.last_sent {
            let wall = now.duration_since(at).as_secs_f64();
            frame.rate = Some(tick.saturating_sub(k) as f64 / wall.max(1e-9));
        }
        self.last_sent = Some((now, tick));
        let switched: Vec<&CommandMark> = self.commands.iter().filter(|c| c.tick <= tick).collect();
        let message = |frame: &super::scene::ShownTick| {
            let mut m = serde_json::json!({ "frame": frame, "verdict": report.verdict });
            if !switched.is_empty() {
                m["commands"] = serde_json::json!(switched);
            }
            m.to_string()
        };
        let full = message(&frame);
        frame.p.clear();
        let light = message(&frame);
        self.hub.frame(full, light);
    }

    /// The run is over: its verdict and violations go to the page, which closes its stream.
    pub fn finish(&self, report: &AuditReport) {
        let marks: Vec<_> = report
            .violations
            .iter()
            .map(|v| serde_json::json!({ "tick": v.tick, "kind": v.kind, "agents": v.agents }))
            .collect();
        let end = serde_json::json!({ "verdict": report.verdict, "violations": marks });
        self.hub.end(end.to_string());
    }
}
