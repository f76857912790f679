//! Tests of plans: timing, limits, the file format and the shipped strategies.

use super::*;
use crate::model::robot::RobotDescription;
use approx::assert_relative_eq;
use proptest::prelude::*;
use std::path::PathBuf;

fn robot() -> RobotDescription {
    RobotDescription::femto_6dof()
}

fn no_settle() -> MotionLimits {
    MotionLimits { settle_s: 0.0, ..MotionLimits::default() }
}

fn move_to(to: JointTarget, label: &str) -> Segment {
    Segment::Move { to, record: true, label: label.into(), through: false }
}

fn plan(segments: Vec<Segment>) -> Plan {
    Plan { name: "t".into(), description: String::new(), segments }
}

/// Closed-form time of a single-joint trapezoid.
fn closed_form(d: f64, v: f64, a: f64) -> f64 {
    if d >= v * v / a {
        d / v + v / a
    } else {
        2.0 * (d / a).sqrt()
    }
}

#[test]
fn move_timing_matches_the_trapezoid_and_triangle_closed_forms() {
    let l = no_settle();
    // (joint, distance): prismatic long (trapezoid, cruise reached) and short (triangle),
    // revolute long and short. v²/a = 10 µm for the piezo, 0.2° for the goniometers.
    for (j, d) in [(2, 300.0), (0, 20.0), (1, 5.0), (2, 0.4), (3, 8.0), (4, 0.5), (5, 0.05)] {
        let (v, a) = if j < 3 { (100.0, 1000.0) } else { (2.0, 20.0) };
        let p = plan(vec![move_to(JointTarget::default().with(j, d / 2.0), "m")]);
        let start = {
            let mut q = [0.0; 6];
            q[j] = -d / 2.0;
            q
        };
        let segs = p.expand(&robot(), start, &l).unwrap();
        assert_eq!(segs.len(), 1);
        let want = closed_form(d, v, a);
        assert_relative_eq!(segs[0].duration_s, want, max_relative = 1e-12);
        // The profile peaks at the joint's speed limit when the cruise is reached.
        let peak = segs[0].velocity_at(want / 2.0)[j];
        if d >= v * v / a {
            assert_relative_eq!(peak, v, max_relative = 1e-12);
        } else {
            assert_relative_eq!(peak, (a * d).sqrt(), max_relative = 1e-12);
        }
    }
    // The paper's 300 µm move at the defaults: 3 s cruise + 0.1 s of ramps + 0.05 s settling.
    let p = plan(vec![move_to(JointTarget::default().with(2, 150.0), "X_w")]);
    let segs = p.expand(&robot(), [0.0, 0.0, -150.0, 0.0, 0.0, 0.0], &MotionLimits::default()).unwrap();
    assert_relative_eq!(segs[0].duration_s, 3.15, max_relative = 1e-12);
}

#[test]
fn synchronized_joints_start_and_end_together_on_a_straight_line() {
    let l = no_settle();
    // q1 by 300 µm (3.1 s alone) with q4 by 1° (0.6 s alone) and q2 by 20 µm.
    let from = [-150.0, -10.0, 0.0, 0.0, 0.0, 0.0];
    let to = [150.0, 10.0, 0.0, 1.0, 0.0, 0.0];
    let segs = plan(vec![move_to(JointTarget::all(to), "sync")]).expand(&robot(), from, &l).unwrap();
    let s = &segs[0];
    // The path limits are min(v_j/d_j) = 100/300 and min(a_j/d_j) = 1000/300, both from q1:
    // q1 alone sets the time.
    assert_relative_eq!(s.duration_s, closed_form(300.0, 100.0, 1000.0), max_relative = 1e-12);
    assert_eq!(s.position_at(s.duration_s), to);
    assert_eq!(s.position_at(0.0), from);
    let n = 1000;
    for i in 1..n {
        let t = s.duration_s * i as f64 / n as f64;
        let p = s.position_at(t);
        let fractions: Vec<f64> =
            (0..6).filter(|&j| to[j] != from[j]).map(|j| (p[j] - from[j]) / (to[j] - from[j])).collect();
        for f in &fractions {
            assert!((f - fractions[0]).abs() < 1e-12, "joints out of step at t = {t}");
            assert!(*f > 0.0 && *f < 1.0, "a joint finished early or not started at t = {t}");
        }
        let v = s.velocity_at(t);
        assert!(v[0].abs() <= 100.0 + 1e-9 && v[3].abs() <= 2.0 + 1e-9);
    }
}

#[test]
fn same_type_joints_take_the_slowest_joints_time() {
    // Three translations of 300, 100 and 3 µm: the 300 µm one sets the duration.
    let from = [0.0; 6];
    let to = [100.0, 3.0, -150.0, 0.0, 0.0, 0.0];
    let s = &plan(vec![move_to(JointTarget::all(to), "xyz")]).expand(&robot(), from, &no_settle()).unwrap()[0];
    assert_relative_eq!(s.duration_s, closed_form(150.0, 100.0, 1000.0), max_relative = 1e-12);
}

#[test]
fn partial_target_keeps_the_other_joints() {
    let start = [12.5, -3.0, 140.0, 1.5, -2.5, 30.0];
    let p = plan(vec![
        move_to(JointTarget { q2_um: Some(7.0), q5_deg: Some(4.0), ..Default::default() }, "partial"),
        Segment::Dwell { duration_s: 1.0, record: false, label: "wait".into() },
        move_to(JointTarget { q6_deg: Some(-30.0), ..Default::default() }, "q6 only"),
    ]);
    let segs = p.expand(&robot(), start, &MotionLimits::default()).unwrap();
    assert_eq!(segs[0].to_display, [12.5, 7.0, 140.0, 1.5, 4.0, 30.0]);
    assert_eq!(segs[1].from_display, segs[0].to_display);
    assert_eq!(segs[1].to_display, segs[0].to_display);
    assert_eq!(segs[2].to_display, [12.5, 7.0, 140.0, 1.5, 4.0, -30.0]);
    // Joints not in the target do not move at all during the move.
    for i in 0..=10 {
        let p = segs[0].position_at(segs[0].duration_s * i as f64 / 10.0);
        assert_eq!([p[0], p[2], p[3], p[5]], [12.5, 140.0, 1.5, 30.0]);
    }
}

#[test]
fn position_is_continuous_within_and_across_segments() {
    let p = plan(vec![
        move_to(JointTarget::all([-150.0, 0.0, -150.0, 0.0, 0.0, 0.0]), "a"),
        Segment::Sweep { from_nm: 1550.0, to_nm: 1570.0, rate_nm_per_s: 10.0, label: "s".into() },
        move_to(JointTarget::default().with(2, 150.0), "b"),
        move_to(JointTarget::default().with(1, 0.3), "tiny"),
        move_to(JointTarget::default().with(1, 0.3), "zero-length"),
        move_to(JointTarget { q4_deg: Some(-4.0), q5_deg: Some(3.0), ..Default::default() }, "rot"),
        Segment::Dwell { duration_s: 0.5, record: true, label: "d".into() },
    ]);
    let limits = MotionLimits::default();
    let segs = p.expand(&robot(), [0.0; 6], &limits).unwrap();
    // Zero-length moves take no time; sweeps take span/rate.
    assert_eq!(segs[4].duration_s, 0.0);
    assert_relative_eq!(segs[1].duration_s, 2.0);
    assert_eq!(segs[1].wavelength_at(1.0), Some(1560.0));
    assert_eq!(segs[1].wavelength_at(9.0), Some(1570.0));
    assert_eq!(segs[0].wavelength_at(0.0), None);
    let total = total_duration_s(&segs);
    for w in segs.windows(2) {
        assert_eq!(w[0].to_display, w[1].from_display);
        assert_eq!(w[0].end_s(), w[1].start_s);
    }
    let at = |t: f64| {
        let s = segment_at(&segs, t).unwrap();
        s.position_at(t - s.start_s)
    };
    // A joint cannot move faster than its limit: bound the jump over each small step.
    let dt = 1e-3;
    let mut t = 0.0;
    let mut prev = at(0.0);
    while t + dt <= total {
        t += dt;
        let p = at(t);
        for j in 0..6 {
            let vmax = if j < 3 { limits.prismatic_speed_um_per_s } else { limits.revolute_speed_deg_per_s };
            assert!((p[j] - prev[j]).abs() <= vmax * dt * (1.0 + 1e-9) + 1e-9, "jump of joint {j} at t = {t}");
        }
        prev = p;
    }
    assert_eq!(at(total), [-150.0, 0.3, 150.0, -4.0, 3.0, 0.0]);
    assert!(segment_at(&segs, total + 1e-6).is_none() && segment_at(&segs, -1e-6).is_none());
}

#[test]
fn limit_violations_name_the_segment_label_and_joint_before_anything_runs() {
    let ok = move_to(JointTarget::default().with(2, 150.0), "fine");
    let p = plan(vec![ok.clone(), ok.clone(), move_to(JointTarget::default().with(2, 200.0), "too far")]);
    let err = p.expand(&robot(), [0.0; 6], &MotionLimits::default()).unwrap_err();
    match &err {
        PlanError::OutOfLimits { segment, label, violation } => {
            assert_eq!((*segment, label.as_str(), violation.joint.as_str()), (2, "too far", "q3"));
            assert_eq!((violation.value, violation.limit), (200.0, 150.0));
        }
        other => panic!("expected OutOfLimits, got {other:?}"),
    }
    assert_eq!(
            err.to_string(),
            "segments[2].to.q3_um: (segment \"too far\") the move ends out of the joint limits: joint q3 = 200.000 µm is 50.000 µm above its upper limit 150.000 µm"
        );
    assert_eq!(err.field_path().as_deref(), Some("segments[2].to.q3_um"));
    // A revolute joint, below its lower limit, reached through a partial target from a start
    // that is itself fine.
    let p = plan(vec![move_to(JointTarget { q5_deg: Some(-12.0), ..Default::default() }, "")]);
    let err = p.expand(&robot(), [0.0, 0.0, 0.0, 9.0, 0.0, 0.0], &MotionLimits::default()).unwrap_err();
    assert_eq!(
            err.to_string(),
            "segments[0].to.q5_deg: the move ends out of the joint limits: joint q5 = -12.000 ° is 2.000 ° below its lower limit -10.000 °"
        );
    // The start itself.
    let err = plan(vec![ok]).expand(&robot(), [0.0, 0.0, 0.0, 0.0, 0.0, 181.0], &MotionLimits::default()).unwrap_err();
    assert!(
        err.to_string().starts_with("the start position is out of the joint limits: joint q6 = 181.000 °"),
        "{err}"
    );
}

#[test]
fn bad_numbers_and_limits_are_refused_with_the_segment() {
    let r = robot();
    let l = MotionLimits::default();
    let cases: Vec<(Segment, &str)> = vec![
            (
                Segment::Sweep { from_nm: 1550.0, to_nm: 1650.0, rate_nm_per_s: 1.0, label: "long".into() },
                "segments[0].to_nm: (segment \"long\") expected a wavelength inside the laser's range 1500-1630 nm, found 1650 nm",
            ),
            (
                Segment::Sweep { from_nm: 1550.0, to_nm: 1570.0, rate_nm_per_s: 0.0, label: "".into() },
                "segments[0].rate_nm_per_s: expected a positive number, found 0",
            ),
            (
                Segment::Sweep { from_nm: 1560.0, to_nm: 1560.0, rate_nm_per_s: 1.0, label: "".into() },
                "segments[0].to_nm: expected to_nm different from from_nm, found both 1560 nm (an empty sweep)",
            ),
            (
                Segment::Dwell { duration_s: -1.0, record: true, label: "w".into() },
                "segments[0].duration_s: (segment \"w\") expected a positive number, found -1",
            ),
            (
                Segment::Dwell { duration_s: f64::INFINITY, record: true, label: "".into() },
                "segments[0].duration_s: expected a finite number, found inf",
            ),
            (
                move_to(JointTarget { q4_deg: Some(f64::NAN), ..Default::default() }, "nan"),
                "segments[0].to.q4_deg: (segment \"nan\") expected a finite number, found NaN",
            ),
        ];
    for (seg, want) in cases {
        let err = plan(vec![seg]).expand(&r, [0.0; 6], &l).unwrap_err();
        assert_eq!(err.to_string(), want);
    }
    let ok = plan(vec![move_to(JointTarget::default(), "")]);
    let bad_limits = MotionLimits { revolute_accel_deg_per_s2: 0.0, ..l };
    assert_eq!(
        ok.expand(&r, [0.0; 6], &bad_limits).unwrap_err().to_string(),
        "motion limit `revolute_accel_deg_per_s2`: expected a finite positive number, found 0"
    );
    let err = ok.expand(&r, [f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0], &l).unwrap_err();
    assert_eq!(err.to_string(), "start position `q1_um`: expected a finite number, found NaN");
    assert_eq!(plan(vec![]).expand(&r, [0.0; 6], &l).unwrap_err(), PlanError::EmptyPlan);
    let narrow = LaserLimits { min_nm: 1555.0, max_nm: 1565.0 };
    let sweep = plan(vec![Segment::Sweep { from_nm: 1550.0, to_nm: 1560.0, rate_nm_per_s: 1.0, label: "".into() }]);
    assert!(sweep.expand(&r, [0.0; 6], &l).is_ok());
    assert!(matches!(
        sweep.expand_with_laser(&r, [0.0; 6], &l, &narrow),
        Err(PlanError::SweepOutOfRange { segment: 0, .. })
    ));
    // A robot whose joints do not match the plan's units is refused, not indexed out of range.
    let mut five = robot();
    five.links.pop();
    let err = ok.expand(&five, [0.0; 6], &l).unwrap_err().to_string();
    assert!(err.starts_with("robot does not fit the plan"), "{err}");
}

fn parse(text: &str) -> Result<Plan, FileError> {
    Plan::from_ron_str(text, Path::new("bad.ron"))
}

#[test]
fn plan_files_parse_partial_targets_and_defaults() {
    let p = parse(
            "Plan(name: \"p\", segments: [\n  Move(to: (q3_um: 150, q5_deg: Some(-2.5))),\n  Dwell(duration_s: 1.0, record: false),\n  Sweep(from_nm: 1550.0, to_nm: 1570.0, rate_nm_per_s: 1.0, label: \"s\"),\n])",
        )
        .unwrap();
    assert_eq!(p.description, "");
    assert_eq!(
        p.segments[0],
        Segment::Move {
            to: JointTarget { q3_um: Some(150.0), q5_deg: Some(-2.5), ..Default::default() },
            record: true,
            label: String::new(),
            through: false,
        }
    );
    assert!(!p.segments[1].is_recorded() && p.segments[2].is_recorded());
    // Save and load again.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p.ron");
    p.save(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("q3_um: 150.0") && !text.contains("q1_um"), "{text}");
    assert!(!text.contains("through"), "written only when set: {text}");
    assert_eq!(Plan::load(&path).unwrap(), p);
}

/// A move `through` its target does not settle there (the next move follows at once), is
/// written and read back, and is refused with its field when a sweep or the plan's end follows.
#[test]
fn a_move_through_its_target_skips_the_settling_and_needs_a_move_after_it() {
    let text = |first: &str| {
        format!("Plan(name: \"p\", segments: [\n  Move(to: (q3_um: 10), through: {first}),\n  Move(to: (q3_um: 20)),\n  Sweep(from_nm: 1550.0, to_nm: 1570.0, rate_nm_per_s: 20.0),\n])")
    };
    let limits = MotionLimits::default();
    let bench_s = |p: &Plan| p.duration_s(&robot(), [0.0; 6], &limits).unwrap();
    let (settled, through) = (parse(&text("false")).unwrap(), parse(&text("true")).unwrap());
    assert!((bench_s(&settled) - bench_s(&through) - limits.settle_s).abs() < 1e-12);
    let timed = through.expand(&robot(), [0.0; 6], &limits).unwrap();
    assert!(matches!(timed[0].motion, TimedMotion::Move { settle_s, .. } if settle_s == 0.0));
    assert!(matches!(timed[1].motion, TimedMotion::Move { settle_s, .. } if settle_s == limits.settle_s));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p.ron");
    through.save(&path).unwrap();
    assert!(std::fs::read_to_string(&path).unwrap().contains("through: true"));
    assert_eq!(Plan::load(&path).unwrap(), through);
    // Before a sweep: refused, with the field.
    let mut bad = through.clone();
    bad.segments.remove(1);
    let err = bad.validate().unwrap_err();
    assert_eq!(err.field_path().as_deref(), Some("segments[0].through"), "{err}");
    assert!(err.to_string().contains("expected another move"), "{err}");
}

#[test]
fn bad_plan_files_give_clear_errors() {
    let cases: &[(&str, &[&str])] = &[
            (
                "Plan(name: \"p\", segments: [\n  Move(to: (q3: 150.0)),\n])",
                &["bad.ron:2:13: Unexpected field named `q3`", "expected one of `q1_um`", "expected a Plan("],
            ),
            ("Plan(name: \"p\", segments: [\n  Move(record: false),\n])", &["bad.ron:2:", "`to`"]),
            ("Plan(name: \"p\", segments: [\n\n  Jump(to: ()),\n])", &["bad.ron:3:", "Jump"]),
            (
                "Plan(name: \"p\", segments: [\n  Sweep(from_nm: 1550.0, to_nm: 1570.0, rate_nm_per_s: -2.0, label: \"before X_w\"),\n])",
                &["bad.ron: field `segments[0].rate_nm_per_s`: (segment \"before X_w\") expected a positive number, found -2"],
            ),
            (
                "Plan(name: \"p\", segments: [Dwell(duration_s: 0.0), Move(to: (q1_um: NaN))])",
                &["bad.ron: field `segments[0].duration_s`", "expected a positive number, found 0"],
            ),
            (
                "Plan(name: \"p\", segments: [Move(to: (q1_um: inf))])",
                &["bad.ron: field `segments[0].to.q1_um`", "expected a finite number, found inf"],
            ),
            ("Plan(name: \"p\", segments: [])", &["bad.ron: field `segments`: expected at least one segment, found none"]),
            ("Plan(name: \"p\", segments: [Move(to: (q2_um: \"ten\"))])", &["bad.ron:1:", "expected a Plan("]),
        ];
    for (text, wants) in cases {
        let err = parse(text).expect_err(text).to_string();
        println!("{err}");
        for want in *wants {
            assert!(err.contains(want), "{text}\n  got `{err}`\n  want `{want}`");
        }
    }
    let err = Plan::load(Path::new("/no/such/plan.ron")).unwrap_err().to_string();
    assert!(err.contains("/no/such/plan.ron"), "{err}");
}

fn shipped(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/plans").join(name)
}

/// Recorded moves as (moving joint, joint vector at the start, distance).
fn recorded_moves(segs: &[TimedSegment]) -> Vec<(usize, [f64; 6], f64)> {
    segs.iter()
        .filter(|s| s.record && matches!(s.motion, TimedMotion::Move { .. }))
        .map(|s| {
            let moving: Vec<usize> = (0..6).filter(|&j| s.to_display[j] != s.from_display[j]).collect();
            assert_eq!(moving.len(), 1, "{}: a recorded move drives exactly one joint", s.label);
            let j = moving[0];
            (j, s.from_display, s.to_display[j] - s.from_display[j])
        })
        .collect()
}

#[test]
fn shipped_strategy1_is_the_papers_translation_strategy() {
    let p = Plan::load(&shipped("strategy1.ron")).unwrap();
    assert_eq!(p, Plan::strategy1());
    let segs = p.expand(&robot(), [0.0; 6], &MotionLimits::default()).unwrap();
    assert_eq!(p.recorded_moves(), 18);
    // Orientation fixed throughout: only translations.
    for s in &segs {
        assert_eq!(&s.to_display[3..], [0.0; 3], "{}", s.label);
    }
    // The paper: lamella positions -150, 0, +150 µm along Z_w (q1), then Y_w (q2), then X_w (q3);
    // at each, two continuous translations: X_w 300 µm and Y_w 20 µm; X_w and Z_w 300 µm;
    // Z_w 300 µm and Y_w 20 µm. 300 µm moves run -150 -> +150, 20 µm ones -10 -> +10
    // (both centred on the stage); the joints not named stay at the centre.
    // q1 moves along Z_w, q2 along Y_w, q3 along X_w.
    let (z, y, x) = (0usize, 1usize, 2usize);
    let mut want = Vec::new();
    for (held, moves) in [(z, [x, y]), (y, [x, z]), (x, [z, y])] {
        for pos in [-150.0, 0.0, 150.0] {
            for m in moves {
                let half = if m == y { 10.0 } else { 150.0 };
                let mut from = [0.0; 6];
                from[held] = pos;
                from[m] = -half;
                want.push((m, from, 2.0 * half));
            }
        }
    }
    assert_eq!(recorded_moves(&segs), want);
    // A wavelength sweep right before and right after every X_w and Z_w move (the sign of dL).
    let mut sweeps_checked = 0;
    for (k, s) in segs.iter().enumerate() {
        if s.record && matches!(s.motion, TimedMotion::Move { .. }) && s.to_display[y] == s.from_display[y] {
            for n in [&segs[k - 1], &segs[k + 1]] {
                assert!(matches!(n.motion, TimedMotion::Sweep { .. }), "{} needs sweeps around it", s.label);
                assert!(n.record);
            }
            sweeps_checked += 2;
        }
    }
    assert_eq!(sweeps_checked, 24);
    let sweeps = segs.iter().filter(|s| matches!(s.motion, TimedMotion::Sweep { .. })).count();
    assert_eq!(sweeps, 24, "no sweep beyond those the paper uses");
    let total = total_duration_s(&segs);
    println!("strategy 1: {} segments, 18 recorded moves, {total:.1} s of bench time", segs.len());
    assert!(total > 120.0 && total < 20.0 * 60.0, "implausible bench time {total} s");
    // It ends where it started.
    assert_eq!(segs.last().unwrap().to_display, [0.0; 6]);
}

#[test]
fn shipped_joint_extras_is_inside_the_limits_with_tilt_scans_and_sweeps() {
    let p = Plan::joint_extras();
    let robot = RobotDescription::femto_6dof();
    let segs = p.expand(&robot, [0.0; 6], &MotionLimits::default()).unwrap();
    let scans = segs.iter().filter(|s| s.record && s.label.starts_with("tilt scan")).count();
    let sweeps = segs.iter().filter(|s| matches!(s.motion, TimedMotion::Sweep { .. })).count();
    assert_eq!((scans, sweeps), (4, 5));
    let d = total_duration_s(&segs);
    assert!(d > 60.0 && d < 300.0, "{d} s");
}

#[test]
fn shipped_strategy2_is_the_papers_rotation_strategy() {
    let p = Plan::load(&shipped("strategy2.ron")).unwrap();
    assert_eq!(p, Plan::strategy2());
    let segs = p.expand(&robot(), [0.0; 6], &MotionLimits::default()).unwrap();
    assert_eq!(p.recorded_moves(), 10);
    for s in &segs {
        assert_eq!(&s.to_display[..3], [0.0; 3], "{}: translations stay at 0", s.label);
        assert_eq!(s.to_display[5], 0.0, "{}: q6 stays at 0", s.label);
    }
    let mut want = Vec::new();
    for (sweeping, other) in [(3usize, 4usize), (4, 3)] {
        for v in [-4.0, -2.0, 0.0, 2.0, 4.0] {
            let mut from = [0.0; 6];
            from[sweeping] = -4.0;
            from[other] = v;
            want.push((sweeping, from, 8.0));
        }
    }
    assert_eq!(recorded_moves(&segs), want);
    let total = total_duration_s(&segs);
    println!("strategy 2: {} segments, 10 recorded moves, {total:.1} s of bench time", segs.len());
    assert!(total > 40.0 && total < 10.0 * 60.0, "implausible bench time {total} s");
    let both = total + Plan::strategy1().duration_s(&robot(), [0.0; 6], &MotionLimits::default()).unwrap();
    println!(
        "both strategies: {:.1} min of bench time (paper: about 30 min for measurement and identification)",
        both / 60.0
    );
    assert!(both < 30.0 * 60.0);
    assert_eq!(segs.last().unwrap().to_display, [0.0; 6]);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, failure_persistence: None, ..ProptestConfig::default() })]

    /// Any move within the limits: ends exactly at the target, never exceeds the joint
    /// speeds, lasts at least as long as each joint alone would need.
    #[test]
    fn random_moves_respect_speed_limits_and_end_on_target(
        from in prop::array::uniform6(-1.0f64..1.0),
        to in prop::array::uniform6(-1.0f64..1.0),
        mask in prop::array::uniform6(any::<bool>()),
    ) {
        let scale = [150.0, 150.0, 150.0, 10.0, 10.0, 180.0];
        let from: [f64; 6] = std::array::from_fn(|j| from[j] * scale[j]);
        let target: [Option<f64>; 6] = std::array::from_fn(|j| mask[j].then_some(to[j] * scale[j]));
        let l = no_settle();
        let segs = plan(vec![move_to(JointTarget::from_values(target), "r")]).expand(&robot(), from, &l).unwrap();
        let s = &segs[0];
        let end = JointTarget::from_values(target).resolve(from);
        prop_assert_eq!(s.position_at(s.duration_s), end);
        for j in 0..6 {
            let (v, a) = if j < 3 { (100.0, 1000.0) } else { (2.0, 20.0) };
            let d = (end[j] - from[j]).abs();
            prop_assert!(s.duration_s >= closed_form(d, v, a) * (1.0 - 1e-12));
            for i in 0..=50 {
                let t = s.duration_s * i as f64 / 50.0;
                prop_assert!(s.velocity_at(t)[j].abs() <= v * (1.0 + 1e-12));
            }
        }
    }
}

#[test]
fn a_plan_without_sweeps_keeps_every_motion_in_order() {
    let p = Plan::joint_extras();
    assert!(p.sweeps() > 0);
    let q = p.without_sweeps();
    assert_eq!(q.sweeps(), 0);
    assert_eq!(q.segments.len(), p.segments.len() - p.sweeps());
    let motions: Vec<&Segment> = p.segments.iter().filter(|s| !matches!(s, Segment::Sweep { .. })).collect();
    assert_eq!(q.segments.iter().collect::<Vec<_>>(), motions);
    assert_eq!(q.recorded_moves(), p.recorded_moves());
}

#[test]
fn an_axis_with_its_own_speed_in_the_robot_file_moves_at_it() {
    // The rotary stage q6 at 10 °/s and 40 °/s², the other axes at the bench's per-type limits.
    let mut fast = robot();
    fast.links[5].limits.speed_per_s = Some(10.0);
    fast.links[5].limits.accel_per_s2 = Some(40.0);
    fast.validate().unwrap();
    let limits = no_settle();
    let rotate = plan(vec![move_to(JointTarget { q6_deg: Some(30.0), ..Default::default() }, "q6")]);
    let t = rotate.duration_s(&fast, [0.0; 6], &limits).unwrap();
    assert_relative_eq!(t, closed_form(30.0, 10.0, 40.0), epsilon = 1e-12);
    let t_type = rotate.duration_s(&robot(), [0.0; 6], &limits).unwrap();
    assert_relative_eq!(t_type, closed_form(30.0, limits.revolute_speed_deg_per_s, limits.revolute_accel_deg_per_s2));
    // A goniometer keeps the per-type limits; moved with q6, the slower of the two sets the time.
    let tilt = plan(vec![move_to(JointTarget { q4_deg: Some(4.0), q6_deg: Some(4.0), ..Default::default() }, "both")]);
    let t_both = tilt.duration_s(&fast, [0.0; 6], &limits).unwrap();
    assert_relative_eq!(t_both, closed_form(4.0, limits.revolute_speed_deg_per_s, limits.revolute_accel_deg_per_s2));
    // Written out, the file keeps the axis's limits; a robot without them writes none.
    let text = ron::ser::to_string(&fast).unwrap();
    assert!(text.contains("speed_per_s:Some(10.0)"), "{text}");
    assert!(!ron::ser::to_string(&robot()).unwrap().contains("speed_per_s"));
}
