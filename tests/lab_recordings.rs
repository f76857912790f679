//! Recordings of random plans by the independent simulator (`independent.rs`), with its multi-beam
//! optics or the second, two-beam model (`two_beam.rs`), calibrated through the path users run
//! (`photorobot calibrate --bench table2-ideal --traces DIR --json`) and scored against the
//! simulator's hidden truth: each determined parameter's error in its reported total σ, and the
//! validation motions planned with the result run on the simulator's own geometry.
//!
//! The public API, for any test that needs recordings whose optics are not ours:
//! - [`random_records`]: a random plan (random poses, moves of one to three joints at once,
//!   sweeps at random poses or none) as the simulator's [`Record`]s;
//! - [`random_truth`]: extrinsics drawn about the design values;
//! - [`LabCase`]: truth, optics, plan, noise seed, hidden intrinsic effect and file style;
//!   [`LabCase::record`] writes its folder of CSV traces; [`LabCase::calibrate`] runs
//!   `calibrate --traces` on it and scores the report ([`CaseOutcome`]).

use crate::independent::{geometry_with, Extrinsics, FileStyle, Hidden, OpticsModel, Record, Recorder, TABLE2};
use crate::two_beam::TwoBeamOptics;
use photorobot_app::cli::run;
use photorobot_core::bench::BenchPreset;
use photorobot_core::model::extrinsics::Extrinsics as CoreExtrinsics;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::validate::forecast::target_nm;
use photorobot_core::validate::{waypoints, ValidationMotion};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde_json::Value;
use std::path::Path;

/// Joint limits the random plans keep to (µm, µm, µm, °, °, °): the stages' travel, and tilts at
/// which the fringes stay visible.
pub const LIMITS: [f64; 6] = [150.0, 150.0, 150.0, 5.0, 5.0, 45.0];

/// A random pose within [`LIMITS`], each joint scaled by `reach` (0-1).
fn random_pose(rng: &mut StdRng, reach: [f64; 6]) -> [f64; 6] {
    std::array::from_fn(|j| rng.random_range(-1.0..=1.0) * LIMITS[j] * reach[j])
}

/// A value in ±`limit` that is `span` away from `from`, on the side with room for it.
fn move_to(rng: &mut StdRng, from: f64, span: f64, limit: f64) -> f64 {
    let up = from + span <= limit;
    let down = from - span >= -limit;
    match (up, down) {
        (true, true) => from + if rng.random_bool(0.5) { span } else { -span },
        (true, false) => from + span,
        (false, true) => from - span,
        (false, false) => {
            if from > 0.0 {
                -limit
            } else {
                limit
            }
        }
    }
}

/// One random motion: translations of one to three stages, rotations of one or two goniometers
/// or the rotary stage, or both at once, from a random pose.
fn random_motion(rng: &mut StdRng, k: usize) -> Record {
    let kind = rng.random_range(0..10);
    let translate = kind < 6 || kind == 9;
    let rotate = kind >= 5;
    let small = [0.8, 0.4, 0.8, 0.5, 0.5, 0.3];
    let mut from = random_pose(rng, small);
    if rng.random_bool(0.5) {
        from[3..].iter_mut().for_each(|v| *v = 0.0);
    }
    let mut to = from;
    if translate {
        let n = rng.random_range(1..=3);
        for _ in 0..n {
            let j = rng.random_range(0..3);
            // Along the beam (q2) the gap changes at once: shorter moves.
            let span = if j == 1 { rng.random_range(10.0..60.0) } else { rng.random_range(80.0..300.0) };
            to[j] = move_to(rng, from[j], span, LIMITS[j]);
        }
    }
    if rotate {
        let j = if rng.random_bool(0.15) { 5 } else { rng.random_range(3..5) };
        let span = if j == 5 { rng.random_range(15.0..60.0) } else { rng.random_range(3.0..9.0) };
        to[j] = move_to(rng, from[j], span, LIMITS[j]);
        if rng.random_bool(0.3) {
            let other = if j == 3 { 4 } else { 3 };
            let span = rng.random_range(1.0..4.0);
            to[other] = move_to(rng, from[other], span, LIMITS[other]);
        }
    }
    Record::Motion { label: format!("motion {k}"), from, to }
}

/// A random plan as the simulator's records: 6 to 16 motions and 0 to 4 sweeps at random poses,
/// interleaved. Labels are neutral ("motion 3", "sweep 1"): what a motion is comes from its data.
pub fn random_records(seed: u64) -> Vec<Record> {
    let mut rng = StdRng::seed_from_u64(seed);
    let motions = rng.random_range(6..=16);
    let sweeps = [0, 1, 2, 3, 3, 4][rng.random_range(0..6)];
    let mut records: Vec<Record> = (0..motions).map(|k| random_motion(&mut rng, k)).collect();
    for s in 0..sweeps {
        let at = random_pose(&mut rng, [0.8, 0.4, 0.8, 0.4, 0.4, 0.3]);
        let centre = 1560.0 + rng.random_range(-5.0..5.0);
        let half = rng.random_range(10.0..20.0);
        let sweep = Record::Sweep {
            label: format!("sweep {s}"),
            at,
            from_nm: centre - half,
            to_nm: centre + half,
            rate_nm_per_s: rng.random_range(5.0..10.0),
        };
        let k = rng.random_range(0..=records.len());
        records.insert(k, sweep);
    }
    records
}

/// Extrinsics drawn about the design values: lamella and fiber tilts within ±1°, the lamella
/// offset within ±5 µm, the beam's origin within ±40 µm across and ±60 µm along the beam.
pub fn random_truth(seed: u64) -> Extrinsics {
    let mut rng = StdRng::seed_from_u64(seed ^ 0x7275_7468);
    let mut u = |half: f64| rng.random_range(-half..=half);
    Extrinsics {
        x_wf_um: 100.0 + u(40.0),
        y_wf_um: 900.0 + u(60.0),
        z_wf_um: 100.0 + u(40.0),
        beta_wf_deg: u(1.0),
        theta_wf_deg: u(1.0),
        z_et_um: u(5.0),
        beta_et_deg: u(1.0),
        theta_et_deg: u(1.0),
    }
}

/// The optics of a case: the independent simulator's multi-beam model, or the two-beam model.
pub fn optics(two_beam: bool) -> OpticsModel {
    match two_beam {
        true => OpticsModel::TwoBeam(TwoBeamOptics::default()),
        false => OpticsModel::MultiBeam(Default::default()),
    }
}

/// One recording: what the simulator hides (truth, optics, intrinsic effect), the plan and the
/// noise, and how its files are written.
#[derive(Debug, Clone)]
pub struct LabCase {
    pub truth: Extrinsics,
    pub optics: OpticsModel,
    pub records: Vec<Record>,
    pub noise_seed: u64,
    pub hidden: Hidden,
    pub style: FileStyle,
}

impl LabCase {
    /// Random plan `plan_seed` with a random truth, recorded with `optics` and noise seed
    /// `noise_seed`, in plain CSV files (no comment lines).
    pub fn random(plan_seed: u64, noise_seed: u64, optics: OpticsModel) -> Self {
        Self {
            truth: random_truth(plan_seed),
            optics,
            records: random_records(plan_seed),
            noise_seed,
            hidden: Hidden::default(),
            style: FileStyle::Plain,
        }
    }

    /// Table II as the truth, the given records.
    pub fn table2(records: Vec<Record>, noise_seed: u64, optics: OpticsModel) -> Self {
        Self { truth: TABLE2, optics, records, noise_seed, hidden: Hidden::default(), style: FileStyle::Plain }
    }

    /// The simulator set up for this case.
    pub fn recorder(&self) -> Recorder {
        let mut r = Recorder::new(self.noise_seed);
        r.truth = self.truth;
        r.optics = self.optics.clone();
        r.hidden = self.hidden;
        r.style = self.style;
        r
    }

    /// Write the case's traces to `dir`; the number of samples.
    pub fn record(&self, dir: &Path) -> usize {
        self.recorder().write_folder(&self.records, dir).expect("the traces written").0
    }

    /// Record into a temporary folder, calibrate through `photorobot calibrate --traces`, and
    /// score the report against the truth.
    pub fn calibrate(&self) -> CaseOutcome {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let traces = dir.path().join("traces");
        self.record(&traces);
        let session = dir.path().join("session");
        let (ok, text) = calibrate_cli(&traces, &session);
        CaseOutcome::score(self, ok, &text)
    }
}

/// `photorobot calibrate --bench table2-ideal --traces DIR --out SESSION --json`: whether it
/// succeeded, and what it printed (then the error).
pub fn calibrate_cli(traces: &Path, session: &Path) -> (bool, String) {
    let args = ["photorobot", "calibrate", "--bench", "table2-ideal", "--traces"].map(String::from);
    let rest = [traces.display().to_string(), "--out".into(), session.display().to_string(), "--json".into()];
    let mut out = Vec::new();
    let result = run(args.into_iter().chain(rest), &mut out);
    let mut text = String::from_utf8_lossy(&out).into_owned();
    if let Err(e) = &result {
        text += &format!("\nerror: {e}");
    }
    (result.is_ok(), text)
}

/// One determined parameter of a report against the truth.
#[derive(Debug, Clone)]
pub struct ParameterError {
    pub name: String,
    /// Value − truth (° or µm).
    pub error: f64,
    /// The reported total σ, and its noise and systematic parts (0 when the report has none).
    pub sigma: f64,
    pub sigma_noise: f64,
    pub sigma_systematic: f64,
}

impl ParameterError {
    /// The error in total σ.
    pub fn in_sigma(&self) -> f64 {
        self.error / self.sigma
    }

    /// The error in noise σ alone.
    pub fn in_noise_sigma(&self) -> f64 {
        self.error / self.sigma_noise
    }
}

/// How one case's calibration came out.
#[derive(Debug, Clone)]
pub struct CaseOutcome {
    /// Optics and truth's summary for tables.
    pub optics: &'static str,
    pub noise_seed: u64,
    /// The report's verdict (`fits`, `does_not_fit`, `ambiguous`), or `error: …`.
    pub verdict: String,
    pub succeeded: bool,
    pub rms_sigma: f64,
    pub traces: usize,
    /// The determined parameters.
    pub determined: Vec<ParameterError>,
    /// Per validation motion planned with the result: (motion, the true gap's peak to peak along
    /// it on the simulator's geometry, the report's 95 % forecast, the target), nm.
    pub validation: Vec<(String, f64, f64, f64)>,
}

impl CaseOutcome {
    fn score(case: &LabCase, succeeded: bool, text: &str) -> Self {
        let mut outcome = CaseOutcome {
            optics: case.optics.name(),
            noise_seed: case.noise_seed,
            verdict: String::new(),
            succeeded,
            rms_sigma: f64::NAN,
            traces: case.records.iter().filter(|r| !matches!(r, Record::Wait { .. })).count(),
            determined: vec![],
            validation: vec![],
        };
        let Ok(doc) = serde_json::from_str::<Value>(text) else {
            outcome.verdict = format!("error: {}", text.lines().last().unwrap_or("no output"));
            return outcome;
        };
        outcome.verdict = doc["fit"]["verdict"].as_str().unwrap_or("missing").to_string();
        outcome.rms_sigma = doc["residual_rms_sigma"].as_f64().unwrap_or(f64::NAN);
        for (name, truth) in case.truth.report_order() {
            let row = doc["parameters"].as_array().and_then(|a| a.iter().find(|r| r["name"] == name));
            let Some(row) = row.filter(|r| r["determined"] == true) else { continue };
            let f = |k: &str| row[k].as_f64().unwrap_or(f64::NAN);
            outcome.determined.push(ParameterError {
                name: name.to_string(),
                error: f("value") - truth,
                sigma: f("sigma"),
                sigma_noise: row["sigma_noise"].as_f64().unwrap_or(f("sigma")),
                sigma_systematic: row["sigma_systematic"].as_f64().unwrap_or(0.0),
            });
        }
        if outcome.verdict == "fits" {
            outcome.validation = validation_on_the_truth(&doc, case);
        }
        outcome
    }

    /// Determined parameters more than `k` total σ from the truth.
    pub fn beyond(&self, k: f64) -> Vec<&ParameterError> {
        self.determined.iter().filter(|p| p.in_sigma().is_nan() || p.in_sigma().abs() > k).collect()
    }

    /// Validation motions whose true gap exceeds the target although the report forecast it
    /// within: a validation promised and not kept.
    pub fn broken_promises(&self) -> Vec<String> {
        self.validation
            .iter()
            .filter(|(_, true_nm, forecast, target)| true_nm > target && (forecast.is_nan() || forecast <= target))
            .map(|(m, t, f, target)| format!("{m}: true gap {t:.1} nm, forecast {f:.1} nm, target {target:.0} nm"))
            .collect()
    }

    /// One line of a table.
    pub fn line(&self) -> String {
        let worst = self.determined.iter().map(|p| p.in_sigma().abs()).fold(0.0, f64::max);
        let worst_noise = self.determined.iter().map(|p| p.in_noise_sigma().abs()).fold(0.0, f64::max);
        let validation: Vec<String> =
            self.validation.iter().map(|(m, t, f, _)| format!("{m} {t:.1} (≤ {f:.1})")).collect();
        format!(
            "{:<10} seed {:>4} {:>3} traces  {:<12} {:>6.2}σ  {} determined, worst {:.1}σ total ({:.1}σ noise){}  validation nm: {}",
            self.optics,
            self.noise_seed,
            self.traces,
            self.verdict,
            self.rms_sigma,
            self.determined.len(),
            worst,
            worst_noise,
            if self.beyond(3.0).is_empty() {
                String::new()
            } else {
                format!(
                    "  BEYOND 3σ: {}",
                    self.beyond(3.0)
                        .iter()
                        .map(|p| format!("{} {:+.1}σ", p.name, p.in_sigma()))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            },
            validation.join(", ")
        )
    }
}

/// The validation motions planned with the report's extrinsics (through the product's inverse
/// model), run on the simulator's geometry: the true gap's peak to peak (nm) along the waypoints
/// and 8 points on each straight joint segment between them, with the report's forecast and
/// target for it.
pub fn validation_on_the_truth(doc: &Value, case: &LabCase) -> Vec<(String, f64, f64, f64)> {
    let Ok(identified) = serde_json::from_value::<CoreExtrinsics>(doc["extrinsics"].clone()) else { return vec![] };
    let preset = BenchPreset::resolve("table2-ideal").expect("the preset");
    let Ok(planning) = PhaseModel::of_preset(&preset, identified) else { return vec![] };
    let mut rows = Vec::new();
    for m in ValidationMotion::ALL {
        let Ok(w) = waypoints(&planning, &identified, m, [0.0; 6], m.waypoint_count()) else { continue };
        let mut gaps_um: Vec<f64> = w
            .windows(2)
            .flat_map(|p| (0..8).map(move |k| std::array::from_fn(|j| p[0][j] + k as f64 / 8.0 * (p[1][j] - p[0][j]))))
            .map(|q| geometry_with(&case.truth, q, &case.hidden).l_um)
            .collect();
        gaps_um.extend(w.last().map(|q| geometry_with(&case.truth, *q, &case.hidden).l_um));
        let (lo, hi) = gaps_um.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(*v), h.max(*v)));
        let forecast = doc["validation_forecast"].as_array().and_then(|a| a.iter().find(|f| f["motion"] == m.name()));
        let nm = |k: &str| forecast.and_then(|f| f[k].as_f64()).unwrap_or(f64::NAN);
        rows.push((m.name().to_string(), (hi - lo) * 1e3, nm("expected_nm"), target_nm(m)));
    }
    rows
}
