//! A second simulator of the bench, written from the physics alone (the paper's Tables I and II, Gaussian optics)
//! and sharing no code with the core: its own kinematic chain, its own multi-beam optics with a
//! tilt loss per pass, its own motions (raised-cosine velocity, rests before and after), sample
//! rate, detector gain, offset and noise, one session-wide clock, and joint readings rounded as
//! an encoder would. It writes a folder of traces in the documented CSV format, as another lab's
//! recorder would, for `calibrate --traces`.

use nalgebra::{Matrix4, Vector3};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::f64::consts::PI;
use std::path::Path;

pub use crate::lab_files::{FileStyle, Row};
pub use crate::two_beam::TwoBeamOptics;

/// The eight extrinsic parameters (µm and °), named as in the paper.
#[derive(Debug, Clone, Copy)]
pub struct Extrinsics {
    pub x_wf_um: f64,
    pub y_wf_um: f64,
    pub z_wf_um: f64,
    pub beta_wf_deg: f64,
    pub theta_wf_deg: f64,
    pub z_et_um: f64,
    pub beta_et_deg: f64,
    pub theta_et_deg: f64,
}

/// Paper Table II.
pub const TABLE2: Extrinsics = Extrinsics {
    x_wf_um: 112.40,
    y_wf_um: 900.0,
    z_wf_um: 113.3,
    beta_wf_deg: 0.732,
    theta_wf_deg: -0.520,
    z_et_um: 1.52,
    beta_et_deg: 0.744,
    theta_et_deg: -0.595,
};

impl Extrinsics {
    /// In the order of the report's parameter table: β_et, θ_et, β_wf, θ_wf, Z_et, x_wf, y_wf, z_wf.
    pub fn report_order(&self) -> [(&'static str, f64); 8] {
        [
            ("beta_et", self.beta_et_deg),
            ("theta_et", self.theta_et_deg),
            ("beta_wf", self.beta_wf_deg),
            ("theta_wf", self.theta_wf_deg),
            ("Z_et", self.z_et_um),
            ("x_wf", self.x_wf_um),
            ("y_wf", self.y_wf_um),
            ("z_wf", self.z_wf_um),
        ]
    }
}

fn rot_x(a: f64) -> Matrix4<f64> {
    let (s, c) = a.sin_cos();
    Matrix4::new(1.0, 0.0, 0.0, 0.0, 0.0, c, -s, 0.0, 0.0, s, c, 0.0, 0.0, 0.0, 0.0, 1.0)
}

fn rot_y(a: f64) -> Matrix4<f64> {
    let (s, c) = a.sin_cos();
    Matrix4::new(c, 0.0, s, 0.0, 0.0, 1.0, 0.0, 0.0, -s, 0.0, c, 0.0, 0.0, 0.0, 0.0, 1.0)
}

fn rot_z(a: f64) -> Matrix4<f64> {
    let (s, c) = a.sin_cos();
    Matrix4::new(c, -s, 0.0, 0.0, s, c, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)
}

fn trans(x: f64, y: f64, z: f64) -> Matrix4<f64> {
    Matrix4::new(1.0, 0.0, 0.0, x, 0.0, 1.0, 0.0, y, 0.0, 0.0, 1.0, z, 0.0, 0.0, 0.0, 1.0)
}

/// End-effector pose in the world for joints in display units (µm, °): the Khalil-Kleinfinger
/// chain of the paper's Table I, each link RotX(α)·RotZ(θ)·TransZ(r) (β = d = 0 on every link).
pub fn end_effector(q: [f64; 6]) -> Matrix4<f64> {
    end_effector_with(q, &Hidden::default())
}

/// Imperfections of this bench that its readings do not show (all zero by default):
/// - `joint_offset`: a zero offset per joint (µm, °): the joint is at its reading plus the offset;
/// - `q3_tilt_mrad`: the q3 stage's axis tilted toward its link frame's x and y (mrad: it moves
///   along (tan t_x, tan t_y, 1), normalised);
/// - `joint_scale_ppm`: gain errors of the q1..q3 stages (ppm: a stage moves its reading times
///   1 + ppm·10⁻⁶);
/// - `pivot_offset_um`: the q4 and q5 rotation axes displaced by these vectors (µm, in the joint's
///   own frame: each turns about the axis through that point instead of its origin);
/// - `drift_nm_per_s`: a thermal drift that lengthens the cavity along the beam with the session
///   clock (nm/s).
#[derive(Debug, Clone, Copy, Default)]
pub struct Hidden {
    pub joint_offset: [f64; 6],
    pub q3_tilt_mrad: [f64; 2],
    pub joint_scale_ppm: [f64; 3],
    pub pivot_offset_um: [[f64; 3]; 2],
    pub drift_nm_per_s: f64,
}

/// [`end_effector`] of a bench with `hidden` imperfections.
pub fn end_effector_with(q: [f64; 6], hidden: &Hidden) -> Matrix4<f64> {
    let link = |alpha: f64, theta: f64, r: f64| rot_x(alpha) * rot_z(theta) * trans(0.0, 0.0, r);
    let m90 = -PI / 2.0;
    let q: [f64; 6] = std::array::from_fn(|j| {
        let scale = if j < 3 { 1.0 + hidden.joint_scale_ppm[j] * 1e-6 } else { 1.0 };
        q[j] * scale + hidden.joint_offset[j]
    });
    let [q4, q5, q6] = [q[3].to_radians(), q[4].to_radians(), q[5].to_radians()];
    let [tx, ty] = hidden.q3_tilt_mrad.map(|m| (m * 1e-3).tan());
    let axis = Vector3::new(tx, ty, 1.0).normalize() * q[2];
    // A rotation about the axis through `p` instead of the frame's origin.
    let about = |p: [f64; 3], angle: f64| trans(p[0], p[1], p[2]) * rot_z(angle) * trans(-p[0], -p[1], -p[2]);
    let [p4, p5] = hidden.pivot_offset_um;
    link(0.0, 0.0, q[0])
        * link(m90, m90, q[1])
        * rot_x(m90)
        * rot_z(m90)
        * trans(axis.x, axis.y, axis.z)
        * about(p4, q4)
        * rot_x(m90)
        * about(p5, q5)
        * rot_z(m90)
        * link(m90, q6, 0.0)
}

/// Signed cavity length L (µm) and the angle between the lamella normal and the fiber axis (rad).
pub fn cavity(e: &Extrinsics, q: [f64; 6]) -> (f64, f64) {
    cavity_with(e, q, &Hidden::default())
}

/// [`cavity`] on a bench with `hidden` imperfections.
pub fn cavity_with(e: &Extrinsics, q: [f64; 6], hidden: &Hidden) -> (f64, f64) {
    let g = geometry_with(e, q, hidden);
    (g.l_um, g.tilt_rad())
}

/// The cavity as optics see it: the signed length along the fiber axis and the axes of the
/// fiber and lamella frames in the world.
#[derive(Debug, Clone, Copy)]
pub struct Geometry {
    /// Signed cavity length L (µm), as docs/conventions.md defines it.
    pub l_um: f64,
    /// The fiber's optical axis (the Y column of its frame) and its X and Z columns.
    pub n_f: Vector3<f64>,
    pub fiber_x: Vector3<f64>,
    pub fiber_z: Vector3<f64>,
    /// The lamella normal (the Z column of the tool frame) and the tool frame's X and Y columns.
    pub n_t: Vector3<f64>,
    pub tool_x: Vector3<f64>,
    pub tool_y: Vector3<f64>,
}

impl Geometry {
    /// The angle between the lamella normal and the fiber axis (rad).
    pub fn tilt_rad(&self) -> f64 {
        self.n_t.dot(&self.n_f).abs().min(1.0).acos()
    }
}

/// The cavity's [`Geometry`] at joints `q` (µm, °) on a bench with `hidden` imperfections.
pub fn geometry_with(e: &Extrinsics, q: [f64; 6], hidden: &Hidden) -> Geometry {
    let fiber =
        trans(e.x_wf_um, e.y_wf_um, e.z_wf_um) * rot_x(e.beta_wf_deg.to_radians()) * rot_z(e.theta_wf_deg.to_radians());
    let tool = end_effector_with(q, hidden)
        * trans(0.0, 0.0, e.z_et_um)
        * rot_x(e.beta_et_deg.to_radians())
        * rot_y(e.theta_et_deg.to_radians());
    let column = |m: &Matrix4<f64>, j: usize| Vector3::new(m[(0, j)], m[(1, j)], m[(2, j)]);
    let (n_f, o_f) = (column(&fiber, 1), column(&fiber, 3));
    let (n_t, o_t) = (column(&tool, 2), column(&tool, 3));
    Geometry {
        l_um: n_t.dot(&(o_t - o_f)) / n_t.dot(&n_f),
        n_f,
        fiber_x: column(&fiber, 0),
        fiber_z: column(&fiber, 2),
        n_t,
        tool_x: column(&tool, 0),
        tool_y: column(&tool, 1),
    }
}

/// The optics of table2-ideal's documented numbers: SMF-28 fiber, LiNbO3 lamella, air at
/// 268.1 ppm, six returning beams each with its Gouy phase, its tilt loss (2m·tilt after m
/// round trips) and its path from the fiber's image in the tilted lamella.
#[derive(Debug, Clone, PartialEq)]
pub struct Optics {
    pub mode_field_radius_um: f64,
    pub fiber_index: f64,
    pub lamella_reflectance: f64,
    pub air_index: f64,
    pub beams: usize,
}

impl Default for Optics {
    fn default() -> Self {
        Self {
            mode_field_radius_um: 5.2,
            fiber_index: 1.4682,
            lamella_reflectance: 0.142,
            air_index: 1.0002681,
            beams: 6,
        }
    }
}

impl Optics {
    /// Reflected power as a fraction of the input for gap |L| (µm), tilt (rad), wavelength (nm).
    pub fn reflectance(&self, gap_um: f64, tilt_rad: f64, wavelength_nm: f64) -> f64 {
        let lambda_um = wavelength_nm * 1e-3;
        let r1 = (self.fiber_index - 1.0) / (self.fiber_index + 1.0);
        // Fresnel, air to the denser lamella: a π phase on reflection.
        let r2 = -self.lamella_reflectance.sqrt();
        let w0 = self.mode_field_radius_um;
        let z_r = PI * w0 * w0 / lambda_um;
        let k = 2.0 * PI / lambda_um;
        let (mut re, mut im) = (r1, 0.0);
        for m in 1..=self.beams {
            let mf = m as f64;
            let weight = (1.0 - r1 * r1) * r2.powi(m as i32) * (-r1).powi(m as i32 - 1);
            let tilt = (-(2.0 * PI * w0 * mf * tilt_rad / lambda_um).powi(2) / 2.0).exp();
            // c_m = 1/(1 - i·m·L/z_R) = (1 + i·u)/(1 + u²)
            let u = mf * gap_um / z_r;
            let (c_re, c_im) = (1.0 / (1.0 + u * u), u / (1.0 + u * u));
            // The m-th returning beam seems to come from the m-th image of the fiber's end in
            // the wedge of fiber face and lamella: images lie on a circle about the wedge's
            // apex, 2·tilt apart, so its distance is a chord, 2|L|·cos θ·sin(mθ)/sin θ.
            let path_um = if tilt_rad > 1e-12 {
                2.0 * gap_um * tilt_rad.cos() * (mf * tilt_rad).sin() / tilt_rad.sin()
            } else {
                2.0 * mf * gap_um
            };
            let phase = -k * self.air_index * path_um;
            let (s, c) = phase.sin_cos();
            let a = weight * tilt;
            re += a * (c_re * c - c_im * s);
            im += a * (c_re * s + c_im * c);
        }
        re * re + im * im
    }
}

/// One recorded file: a motion between two joint vectors, or a sweep at fixed joints.
#[derive(Debug, Clone)]
pub enum Record {
    Motion {
        label: String,
        from: [f64; 6],
        to: [f64; 6],
    },
    Sweep {
        label: String,
        at: [f64; 6],
        from_nm: f64,
        to_nm: f64,
        rate_nm_per_s: f64,
    },
    /// Nothing recorded: the stages go to `at` and wait `s` seconds there.
    Wait {
        at: [f64; 6],
        s: f64,
    },
}

/// The records of a plan file in the project's format, as a lab's recorder would run it: an
/// unrecorded move or a pause only moves the pose and the clock, a recorded move is a motion from
/// the pose it starts at, a sweep is recorded where the stages stand.
pub fn records_of(plan: &photorobot_core::plan::Plan) -> Vec<Record> {
    use photorobot_core::plan::Segment;
    let (mut at, mut out) = ([0.0; 6], Vec::new());
    for seg in &plan.segments {
        match seg {
            Segment::Move { to, record, label, .. } => {
                let t = to;
                let targets = [t.q1_um, t.q2_um, t.q3_um, t.q4_deg, t.q5_deg, t.q6_deg];
                let next: [f64; 6] = std::array::from_fn(|j| targets[j].unwrap_or(at[j]));
                out.push(match record {
                    true => Record::Motion { label: label.clone(), from: at, to: next },
                    false => Record::Wait { at: next, s: 0.0 },
                });
                at = next;
            }
            Segment::Sweep { from_nm, to_nm, rate_nm_per_s, label } => out.push(Record::Sweep {
                label: label.clone(),
                at,
                from_nm: *from_nm,
                to_nm: *to_nm,
                rate_nm_per_s: *rate_nm_per_s,
            }),
            Segment::Dwell { duration_s, .. } => out.push(Record::Wait { at, s: *duration_s }),
        }
    }
    out
}

/// How the joints move between two poses in time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Profile {
    /// Constant velocity from start to end.
    Constant,
    /// Velocity (1 - cos)/2-shaped: starts and stops smoothly, peak π/2 times the mean.
    RaisedCosine,
}

impl Profile {
    /// Fraction of the motion done at fraction `s` of its duration.
    fn progress(self, s: f64) -> f64 {
        match self {
            Profile::Constant => s,
            Profile::RaisedCosine => (1.0 - (PI * s).cos()) / 2.0,
        }
    }

    /// Duration relative to a constant-velocity motion at the same peak speed.
    fn duration_factor(self) -> f64 {
        match self {
            Profile::Constant => 1.0,
            Profile::RaisedCosine => PI / 2.0,
        }
    }
}

/// The optics a recording is made with: this simulator's multi-beam model ([`Optics`]), or the
/// second, deliberately different model ([`TwoBeamOptics`]).
#[derive(Debug, Clone, PartialEq)]
pub enum OpticsModel {
    MultiBeam(Optics),
    TwoBeam(TwoBeamOptics),
}

impl OpticsModel {
    /// Reflected power as a fraction of the input for the cavity `g` at `wavelength_nm`.
    pub fn reflectance(&self, g: &Geometry, wavelength_nm: f64) -> f64 {
        match self {
            OpticsModel::MultiBeam(o) => o.reflectance(g.l_um.abs(), g.tilt_rad(), wavelength_nm),
            OpticsModel::TwoBeam(o) => o.reflectance(g, wavelength_nm),
        }
    }

    /// A short name for tables: `multi-beam` or `two-beam`.
    pub fn name(&self) -> &'static str {
        match self {
            OpticsModel::MultiBeam(_) => "multi-beam",
            OpticsModel::TwoBeam(_) => "two-beam",
        }
    }
}

/// The recorder: detector and motion settings unlike the core's virtual bench.
pub struct Recorder {
    pub truth: Extrinsics,
    pub optics: OpticsModel,
    pub laser_nm: f64,
    pub sample_rate_hz: f64,
    pub prismatic_um_per_s: f64,
    pub revolute_deg_per_s: f64,
    pub rest_s: f64,
    /// Joint motion in time: constant velocity, or a raised-cosine velocity (smooth starts).
    pub profile: Profile,
    /// Photodiode: volts per unit reflectance, dark offset (V), white noise relative to the
    /// fringe amplitude at q = 0.
    pub gain_v: f64,
    pub offset_v: f64,
    pub noise_rel_fringe: f64,
    pub seed: u64,
    /// What the bench hides from its readings.
    pub hidden: Hidden,
    /// The session clock at the start of the first record (s).
    pub start_clock_s: f64,
    /// How the files are written: our format with label lines, or another lab's export.
    pub style: FileStyle,
}

impl Recorder {
    pub fn new(seed: u64) -> Self {
        Self {
            truth: TABLE2,
            optics: OpticsModel::MultiBeam(Optics::default()),
            laser_nm: 1560.0,
            sample_rate_hz: 4000.0,
            prismatic_um_per_s: 80.0,
            revolute_deg_per_s: 1.5,
            rest_s: 0.05,
            profile: Profile::Constant,
            gain_v: 2.5,
            offset_v: 0.0,
            noise_rel_fringe: 1e-3,
            seed,
            hidden: Hidden::default(),
            start_clock_s: 3.7,
            style: FileStyle::Ours,
        }
    }

    /// The cavity at joints `q` and session time `clock_s` (the hidden drift lengthens it).
    fn geometry(&self, q: [f64; 6], clock_s: f64) -> Geometry {
        let mut g = geometry_with(&self.truth, q, &self.hidden);
        g.l_um += g.l_um.signum() * self.hidden.drift_nm_per_s * clock_s * 1e-3;
        g
    }

    fn signal(&self, q: [f64; 6], wavelength_nm: f64, clock_s: f64) -> f64 {
        self.offset_v + self.gain_v * self.optics.reflectance(&self.geometry(q, clock_s), wavelength_nm)
    }

    /// Peak-to-peak fringe amplitude (V) at q = 0, over one fringe of gap.
    fn fringe_amplitude_v(&self) -> f64 {
        let g = self.geometry([0.0; 6], 0.0);
        let half = self.laser_nm * 1e-3 / 2.0;
        let values: Vec<f64> = (0..400)
            .map(|i| {
                let at = Geometry { l_um: g.l_um - half * i as f64 / 400.0 * g.l_um.signum(), ..g };
                self.gain_v * self.optics.reflectance(&at, self.laser_nm)
            })
            .collect();
        values.iter().cloned().fold(f64::MIN, f64::max) - values.iter().cloned().fold(f64::MAX, f64::min)
    }

    fn duration_s(&self, from: &[f64; 6], to: &[f64; 6]) -> f64 {
        let t = (0..6)
            .map(|j| (to[j] - from[j]).abs() / if j < 3 { self.prismatic_um_per_s } else { self.revolute_deg_per_s })
            .fold(0.0, f64::max);
        t * self.profile.duration_factor()
    }

    /// Write every record to `dir` as `NNN.csv` in [`Recorder::style`], on one clock from
    /// `start_clock_s` (setup moves between records and waits take their time unrecorded).
    /// Returns the number of samples written and the clock at the end (s).
    pub fn write_folder(&self, records: &[Record], dir: &Path) -> std::io::Result<(usize, f64)> {
        std::fs::create_dir_all(dir)?;
        let mut rng = StdRng::seed_from_u64(self.seed);
        let noise = Normal::new(0.0, self.noise_rel_fringe * self.fringe_amplitude_v()).expect("a finite σ");
        let dt = 1.0 / self.sample_rate_hz;
        let (mut clock, mut at, mut samples, mut files) = (self.start_clock_s, [0.0; 6], 0, 0);
        let encoder = |q: [f64; 6]| q.map(|v| (v * 1e4).round() / 1e4);
        for record in records {
            let mut rows: Vec<Row> = Vec::new();
            let mut row = |t: f64, q: [f64; 6], nm: f64, rng: &mut StdRng| {
                let irradiance = self.signal(q, nm, t) + noise.sample(rng);
                rows.push(Row { t_s: t, q: encoder(q), wavelength_nm: nm, irradiance });
            };
            let (label, start) = match record {
                Record::Motion { label, from, .. } => (label, *from),
                Record::Sweep { label, at, .. } => (label, *at),
                Record::Wait { at: pose, s } => {
                    clock += self.duration_s(&at, pose) + s;
                    at = *pose;
                    continue;
                }
            };
            clock += self.duration_s(&at, &start) + 0.3;
            match record {
                Record::Motion { from, to, .. } => {
                    let moving = self.duration_s(from, to);
                    let total = moving + 2.0 * self.rest_s;
                    let n = (total * self.sample_rate_hz) as usize;
                    for k in 0..n {
                        let t = k as f64 * dt;
                        let s = ((t - self.rest_s) / moving).clamp(0.0, 1.0);
                        let s = self.profile.progress(s);
                        let q: [f64; 6] = std::array::from_fn(|j| from[j] + s * (to[j] - from[j]));
                        row(clock + t, q, self.laser_nm, &mut rng);
                    }
                    clock += total;
                    at = *to;
                }
                Record::Sweep { at: pose, from_nm, to_nm, rate_nm_per_s, .. } => {
                    let total = (to_nm - from_nm).abs() / rate_nm_per_s;
                    let n = (total * self.sample_rate_hz) as usize;
                    for k in 0..n {
                        let t = k as f64 * dt;
                        row(clock + t, *pose, from_nm + (to_nm - from_nm) * t / total, &mut rng);
                    }
                    clock += total;
                    at = *pose;
                }
                Record::Wait { .. } => unreachable!("a wait records nothing: handled above"),
            }
            samples += rows.len();
            std::fs::write(dir.join(format!("{files:03}.csv")), self.style.file(label, &rows))?;
            files += 1;
        }
        Ok((samples, clock))
    }
}

/// Motions much like the paper's, at offsets of our own, with three sweeps at poses other than
/// strategy 1's: X and Z translations at lateral offsets, short Y translations, q4 and q5
/// rotations of ±4° (one at a lateral offset), a q6 rotation.
pub fn lab_records() -> Vec<Record> {
    let motion = |label: String, from: [f64; 6], to: [f64; 6]| Record::Motion { label, from, to };
    let sweep = |label: &str, at: [f64; 6]| Record::Sweep {
        label: label.into(),
        at,
        from_nm: 1545.0,
        to_nm: 1575.0,
        rate_nm_per_s: 8.0,
    };
    let mut r = vec![sweep("scan at home", [0.0; 6])];
    for q1 in [-120.0, 0.0, 120.0] {
        r.push(motion(format!("X at Z {q1}"), [q1, 0.0, -150.0, 0.0, 0.0, 0.0], [q1, 0.0, 150.0, 0.0, 0.0, 0.0]));
    }
    r.push(sweep("scan back", [0.0, -60.0, 0.0, 0.0, 0.0, 0.0]));
    for q3 in [-90.0, 90.0] {
        r.push(motion(format!("Z at X {q3}"), [-150.0, 0.0, q3, 0.0, 0.0, 0.0], [150.0, 0.0, q3, 0.0, 0.0, 0.0]));
    }
    for (q1, q3) in [(0.0, 0.0), (100.0, -100.0)] {
        r.push(motion(format!("Y at {q1},{q3}"), [q1, -15.0, q3, 0.0, 0.0, 0.0], [q1, 15.0, q3, 0.0, 0.0, 0.0]));
    }
    r.push(sweep("scan tilted", [80.0, 0.0, -80.0, 0.0, 2.0, 0.0]));
    for other in [-3.0, 0.0, 3.0] {
        r.push(motion(
            format!("gonio A at B {other}"),
            [0.0, 0.0, 0.0, -4.0, other, 0.0],
            [0.0, 0.0, 0.0, 4.0, other, 0.0],
        ));
        r.push(motion(
            format!("gonio B at A {other}"),
            [0.0, 0.0, 0.0, other, -4.0, 0.0],
            [0.0, 0.0, 0.0, other, 4.0, 0.0],
        ));
    }
    r.push(motion("gonio A off centre".into(), [60.0, 0.0, -60.0, -3.0, 0.0, 0.0], [60.0, 0.0, -60.0, 3.0, 0.0, 0.0]));
    r.push(motion("rotary".into(), [0.0, 0.0, 0.0, 0.0, 0.0, -15.0], [0.0, 0.0, 0.0, 0.0, 0.0, 15.0]));
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The figures docs/conventions.md derives from Table II, from this chain and this measurement equation.
    #[test]
    fn the_chain_gives_the_reference_figures() {
        let e = end_effector([0.0; 6]);
        let rows = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]];
        for (i, row) in rows.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                assert!((e[(i, j)] - v).abs() < 1e-12, "wTe({i},{j}) = {}", e[(i, j)]);
            }
        }
        let (l0, tilt) = cavity(&TABLE2, [0.0; 6]);
        assert!((l0 + 898.830).abs() < 1e-3, "L(0) = {l0}");
        assert!((tilt * 1e3 - 19.46).abs() < 0.01, "tilt {tilt}");
        let (l, _) = cavity(&TABLE2, [10.0, -20.0, 30.0, 1.0, -2.0, 3.0]);
        assert!((l + 923.295).abs() < 1e-3, "L = {l}");
    }

    /// The Gaussian closed forms: first-pass tilt loss 0.88 at 1°, and a two-beam visibility near 0.2 at
    /// |L| ≈ 900 µm.
    #[test]
    fn the_optics_give_the_reference_figures() {
        let o = Optics::default();
        let lambda_um: f64 = 1.56;
        let loss = (-(2.0 * PI * 5.2 * 1f64.to_radians() / lambda_um).powi(2)).exp();
        assert!((loss - 0.88).abs() < 0.01, "tilt loss {loss}");
        let values: Vec<f64> = (0..200).map(|i| o.reflectance(898.0 + 0.78 * i as f64 / 200.0, 0.0, 1560.0)).collect();
        let (lo, hi) =
            (values.iter().cloned().fold(f64::MAX, f64::min), values.iter().cloned().fold(f64::MIN, f64::max));
        let visibility = (hi - lo) / (hi + lo);
        assert!((0.1..0.3).contains(&visibility), "visibility {visibility}");
    }
}
