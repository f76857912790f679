//! The diagnosis' thresholds and extraction settings, shared by the workflow and the motions.

use crate::identify::measurements::ExtractOptions;

/// The residual counts as at the noise floor up to this multiple of it (whitened rms).
pub const NOISE_FLOOR_FACTOR: f64 = 1.5;
/// Expected score at typical size below which a candidate needs discriminating motions.
pub const DETECTABLE_SCORE: f64 = 25.0;
/// Absorbed share from which a candidate counts as equivalent to an extrinsic change.
pub const EQUIVALENT_SHARE: f64 = 0.999;
/// How the diagnosis turns traces into observations: σ floors at a bench's noise (dL
/// 2 nm, absolute gaps 20 nm), what a bench reaches beyond the fringe analysis' own σ (stage
/// noise, sweep-model limits); the identifier's floors are tighter.
pub const EXTRACT_OPTIONS: ExtractOptions = ExtractOptions {
    points_per_motion: 4,
    sigma_floor_nm: 2.0,
    rotation_sigma_floor_nm: 2.5,
    gap_sigma_floor_um: 0.02,
    amplitudes_from_rotations: true,
    amplitude_neighbours: true,
    gap_across_pauses: true,
    shaped: false,
    max_amplitudes_per_trace: None,
    sweeps: true,
};
/// How the diagnosis analyses the traces again once an effect is named ([`EXTRACT_OPTIONS`],
/// tracked with the model's fringe shape). The first extraction estimates the fringe's shape
/// from the data, because the calibrated model's tilt can be a degree off and the shaped
/// tracker then goes wrong (see `measure::analyse_with`); by the re-analysis the extrinsics are
/// refitted and the named effects are in the model, optical ones included, so the model's shape
/// is the better one: with the data-estimated shape a hidden q4 pivot offset drags a spurious
/// joint scale error along with it (see docs/diagnosis.md).
pub const REANALYSE_OPTIONS: ExtractOptions = ExtractOptions { shaped: true, sweeps: false, ..EXTRACT_OPTIONS };
/// A re-analysis of the traces with the model is refused when the model's whitened rms on it
/// exceeds its rms on the analysis it would replace by more than this factor, and the noise
/// floor ([`NOISE_FLOOR_FACTOR`]): the motion hint then led the tracking astray. Under optics
/// unlike the model's (a two-beam fringe) the re-analysis after a wrongly named effect doubled
/// the misfit, and each later naming built on the data that effect had shaped.
pub const REANALYSIS_RMS_TOLERANCE: f64 = 1.1;
/// Label prefix of the discriminating motions ([`motions::pool`]).
pub const DISCRIMINATING_PREFIX: &str = "D ";
/// At most this many discriminating motions per design: room for a reversal of each prismatic
/// stage (out and back) beside the q6 rotations that show a pivot offset best.
pub const MAX_MOTIONS: usize = 14;
/// At most this many rounds of discriminating motions run on a bench. A round's motions are
/// chosen from the model's templates; the traces they give can show less than the templates
/// promised (a q6 turn predicted to show a 0.5 nm/s drift at a score of 28 gave 18 as recorded),
/// so the design is done again on the data, without the motions recorded, while no candidate
/// is significant and some target still lacks evidence the pool can add (the 30 s dwell, then).
/// Once a candidate is significant there is something to name, and the naming goes first.
pub const MAX_DESIGN_ROUNDS: usize = 3;
/// At most this many effects are added: femto-lab's five (six parameters) and room to spare.
pub const MAX_EFFECTS: usize = 8;
/// An added effect is exchanged for another candidate when, refitted in its place with the other
/// effects, that one lowers χ² by more than this (2σ for one parameter).
pub const EXCHANGE_MARGIN: f64 = 4.0;
/// An effect added earlier is removed again when, refitted with those added after it, its
/// estimate is within this many σ of neutral: a later one explains what it took up.
pub const REMOVE_BELOW_SIGMA: f64 = 3.0;
/// Another branch of the calibration replaces the current extrinsics when its refit lowers χ²
/// by more than this (3σ for one parameter): the two are otherwise a tie the data do not settle.
pub const BRANCH_MARGIN_CHI2: f64 = 9.0;
