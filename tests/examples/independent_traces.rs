//! Writes a folder of traces recorded by the independent simulator (`independent.rs`: code of its
//! own, Table II as its truth), to calibrate with `photorobot calibrate --traces`:
//!
//!     cargo run --release -p photorobot-e2e --example independent_traces -- DIR [SEED] [--raised-cosine]
//!     cargo run --release -p photorobot -- calibrate --bench table2-ideal --traces DIR --out S
//!
//! Motions run at constant velocity unless `--raised-cosine` (smooth starts and stops). The same
//! motions as a plan for the core's own simulator (`photorobot simulate --plan FILE`):
//!
//!     cargo run --release -p photorobot-e2e --example independent_traces -- plan FILE

use photorobot_e2e::independent::{lab_records, Recorder};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(dir) = args.first() else {
        eprintln!("usage: independent_traces DIR [SEED]");
        std::process::exit(2);
    };
    if dir == "truth" {
        use photorobot_e2e::independent::{cavity, Record, TABLE2};
        for (i, r) in lab_records().iter().enumerate() {
            if let Record::Motion { label, from, to } = r {
                let path = |q: [f64; 6]| {
                    let (l, tilt) = cavity(&TABLE2, q);
                    l.abs() * tilt.cos()
                };
                println!("{i:03} {label}: optical gap change {:.4} µm", path(*to) - path(*from));
            }
        }
        return;
    }
    if dir == "plan" {
        write_plan(&args[1]);
        return;
    }
    let seed = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(11);
    let mut recorder = Recorder::new(seed);
    if args.iter().any(|a| a == "--raised-cosine") {
        recorder.profile = photorobot_e2e::independent::Profile::RaisedCosine;
    }
    match recorder.write_folder(&lab_records(), std::path::Path::new(dir)) {
        Ok((n, _)) => println!("{} traces, {n} samples in {dir}", lab_records().len()),
        Err(e) => {
            eprintln!("{dir}: {e}");
            std::process::exit(1);
        }
    }
}

/// The same motions as a plan file for `photorobot simulate --plan` (the core's own simulator).
fn write_plan(file: &str) {
    use photorobot_core::plan::{JointTarget, Plan, Segment};
    use photorobot_e2e::independent::Record;
    let mv = |to: [f64; 6], record: bool, label: &str| Segment::Move {
        to: JointTarget::all(to),
        record,
        label: label.into(),
        through: false,
    };
    let mut segments = Vec::new();
    for r in lab_records() {
        match r {
            Record::Motion { label, from, to } => {
                segments.push(mv(from, false, "setup"));
                segments.push(mv(to, true, &label));
            }
            Record::Sweep { label, at, from_nm, to_nm, rate_nm_per_s } => {
                segments.push(mv(at, false, "setup"));
                segments.push(Segment::Sweep { from_nm, to_nm, rate_nm_per_s, label });
            }
            Record::Wait { at, s } => {
                segments.push(mv(at, false, "setup"));
                if s > 0.0 {
                    segments.push(Segment::Dwell { duration_s: s, record: false, label: "wait".into() });
                }
            }
        }
    }
    let plan = Plan { name: "independent lab motions".into(), description: String::new(), segments };
    plan.save(std::path::Path::new(file)).expect("the plan saved");
}
