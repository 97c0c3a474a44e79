//! The 3-D viewer: one page (three.js, vendored under `assets/viewer/` and embedded in the
//! binary) that replays a finished run from `replay.html` (self-contained: works from `file://`
//! with no network) or follows a live team over Server-Sent Events (`launch --serve`).
//!
//! The page is a template plus JSON blocks: three.js's ES modules travel as JSON strings and are
//! turned into `blob:` module URLs by the page, because a `file://` page may not import modules
//! from files, and a CDN is not allowed.

pub mod live;
pub mod scene;
mod serve;

use std::path::{Path, PathBuf};

use cdm_scenario::{Checks, Scenario};

use cdm_report::data::{read_audit, read_timeline, stream_ticks, ReadError};
use scene::{frame_stride, CommandMark, Scene, ShownTickMaker};

pub use serve::{serve_page, ServeError};

/// Size budget of replay.html: telemetry is decimated to stay within it (N = 1000 included).
pub const REPLAY_BUDGET_BYTES: usize = 20 << 20;

/// three.js r187 (npm `three@0.187.0`), the page and its script.
const THREE_CORE: &str = include_str!("../assets/viewer/three.core.js");
const THREE_MODULE: &str = include_str!("../assets/viewer/three.module.js");
const ORBIT_CONTROLS: &str = include_str!("../assets/viewer/OrbitControls.js");
const PAGE: &str = include_str!("../assets/viewer/viewer.html");
const APP: &str = include_str!("../assets/viewer/viewer.js");

/// A run directory the viewer cannot show.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    #[error(transparent)]
    Read(#[from] ReadError),
    #[error(transparent)]
    Write(#[from] cdm_records::rundir::RunDirError),
}

/// The whole run, decimated to [`REPLAY_BUDGET_BYTES`] (the last tick is always kept).
pub fn replay_scene(dir: &Path) -> Result<Scene, ViewerError> {
    let sc_path = dir.join("scenario.toml");
    let scenario = Scenario::load(&sc_path, Checks::Member).map_err(|e| ReadError::Invalid {
        path: sc_path.clone(),
        message: e.to_string(),
    })?;
    let audit_path = dir.join("audit.json");
    let numbers = read_audit(&audit_path)?;
    let timeline = read_timeline(&audit_path)?;
    let mut scene = Scene::new(
        &scenario,
        numbers.delta_m,
        numbers.eps_m,
        numbers.lambda_cd_min,
    )
    .with_repairs(&scenario, &numbers.repairs);
    scene.verdict = timeline.verdict;
    scene.commands = cdm_records::commands::read_commands(dir)
        .map_err(|e| ReadError::Invalid {
            path: dir.join(cdm_records::commands::COMMANDS_FILE),
            message: e.to_string(),
        })?
        .iter()
        .map(CommandMark::from)
        .collect();
    scene.violations = timeline.violations;
    let n = scenario.formation.members.len();
    scene.stride = frame_stride(timeline.ticks.max(1), n, REPLAY_BUDGET_BYTES);
    let maker = ShownTickMaker::new(&scenario, scene.half_height_m);
    let mut seen = 0u64;
    let mut last = None;
    stream_ticks(dir, &scenario, &numbers.losses, |tp| {
        if seen.is_multiple_of(scene.stride) {
            scene.frames.push(maker.frame(&scenario, &tp));
            last = None;
        } else {
            last = Some(maker.frame(&scenario, &tp));
        }
        seen += 1;
    })?;
    scene.frames.extend(last);
    Ok(scene)
}

/// A JSON value that can sit inside a `<script>` element (no `</` sequence survives).
fn script_json(value: &impl serde::Serialize) -> String {
    // Serialising plain data (strings, numbers, vectors) cannot fail.
    serde_json::to_string(value)
        .unwrap_or_else(|_| "null".to_owned())
        .replace("</", "<\\/")
}

/// The viewer page: the replay of `scene`, or (None) the live page that fetches `/scene.json`
/// and follows `/events`.
pub fn page(scene: Option<&Scene>) -> String {
    let block = |id: &str, json: String| {
        format!("<script type=\"application/json\" id=\"{id}\">{json}</script>\n")
    };
    let mut blocks = String::new();
    blocks += &block("src-three-core", script_json(&THREE_CORE));
    blocks += &block("src-three", script_json(&THREE_MODULE));
    blocks += &block("src-orbit", script_json(&ORBIT_CONTROLS));
    blocks += &block("src-app", script_json(&APP));
    blocks += &block(
        "cdm-scene",
        scene.map_or_else(|| "null".to_owned(), script_json),
    );
    PAGE.replace("<!--CDM_BLOCKS-->", &blocks)
}

/// Writes `replay.html` into a run directory and returns its path.
pub fn write_replay(dir: &Path) -> Result<PathBuf, ViewerError> {
    let scene = replay_scene(dir)?;
    let path = dir.join("replay.html");
    cdm_records::rundir::write_atomic(&path, page(Some(&scene)).as_bytes())?;
    Ok(path)
}
