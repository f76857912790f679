//! `photorobot frames [--q ..] [--extrinsics FILE] [--robot FILE] [--json]`: every frame's pose, the signed
//! cavity length and the reflection point. Owns only argument parsing and printing; the work is
//! `photorobot_core::model::frames`.

use super::common::{json_text, load_extrinsics, CliError};
use photorobot_core::model::frames::FrameTree;
use photorobot_core::model::kinematics::Chain;
use photorobot_core::model::robot::RobotDescription;
use serde_json::json;
use std::io::Write;
use std::path::PathBuf;

/// Arguments of `photorobot frames`.
#[derive(Debug, clap::Args)]
pub struct FramesArgs {
    /// Joint values q1,..,q6: prismatic joints in µm, revolute joints in degrees (default: all 0).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, value_name = "q1,..,q6")]
    pub q: Option<Vec<f64>>,
    /// Extrinsic parameters file (RON; default: the paper's Table II, assets/extrinsics/table2.ron).
    #[arg(long, value_name = "FILE")]
    pub extrinsics: Option<PathBuf>,
    /// Robot description file (RON; default: assets/robots/femto-6dof.ron).
    #[arg(long, value_name = "FILE")]
    pub robot: Option<PathBuf>,
    /// Print JSON (lengths in µm) instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The robot description file given, or the embedded femto-6dof robot when none is.
fn load_robot(path: &Option<PathBuf>) -> Result<RobotDescription, CliError> {
    Ok(match path {
        Some(p) => RobotDescription::load(p)?,
        None => RobotDescription::femto_6dof(),
    })
}

/// Joint vector from `--q` in display units (µm, °), checked for length, finiteness and limits.
fn joints_from_arg(robot: &RobotDescription, q: &Option<Vec<f64>>) -> Result<Vec<f64>, CliError> {
    let q_display = q.clone().unwrap_or_else(|| vec![0.0; robot.dof()]);
    if q_display.len() != robot.dof() {
        return Err(CliError::Argument {
            argument: "--q",
            problem: format!(
                "expected {} comma-separated joint values ({}), found {}",
                robot.dof(),
                robot.joint_names().join(","),
                q_display.len()
            ),
        });
    }
    if let Some((i, v)) = q_display.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(CliError::Argument {
            argument: "--q",
            problem: format!("joint {} must be a finite number, found {v}", robot.links[i].name),
        });
    }
    let q = robot.q_from_display(&q_display);
    Chain::new(robot.clone()).check_limits(&q)?;
    Ok(q)
}

/// Print the frame tree at the joints of `--q`.
pub fn frames(a: &FramesArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let robot = load_robot(&a.robot)?;
    let extrinsics = load_extrinsics(&a.extrinsics)?;
    let q = joints_from_arg(&robot, &a.q)?;
    let chain = Chain::new(robot.clone());
    let tree = FrameTree::new(&chain, &extrinsics, &q);
    let q_display = robot.q_to_display(&q);
    if a.json {
        let cavity = match &tree.cavity {
            Ok(c) => json!({
                "cavity_length_um": c.length_um,
                "gap_um": c.length_um.abs(),
                "reflection_point_world_um": [c.reflection_point_world_um.x, c.reflection_point_world_um.y, c.reflection_point_world_um.z],
                "reflection_point_tool_um": [c.reflection_point_tool_um.x, c.reflection_point_tool_um.y, c.reflection_point_tool_um.z],
                "n_f": [c.n_f.x, c.n_f.y, c.n_f.z],
                "n_t": [c.n_t.x, c.n_t.y, c.n_t.z],
                "tilt_mrad": c.tilt_rad * 1e3,
            }),
            Err(e) => json!({ "cavity_length_um": null, "cavity_error": e.to_string() }),
        };
        let joints: Vec<_> = robot
            .links
            .iter()
            .zip(&q_display)
            .map(|(l, v)| json!({ "name": l.name, "value": v, "unit": l.joint.display_unit() }))
            .collect();
        let mut doc = json!({
            "robot": robot.name,
            "q": joints,
            "frames": tree.records(),
        });
        doc.as_object_mut().unwrap().extend(cavity.as_object().unwrap().clone());
        writeln!(out, "{}", json_text(&doc)?)?;
        return Ok(());
    }
    let origin = |p: &Option<PathBuf>, default: &str| match p {
        Some(p) => p.display().to_string(),
        None => format!("{default} (embedded)"),
    };
    writeln!(out, "robot:      {} ({})", robot.name, origin(&a.robot, "assets/robots/femto-6dof.ron"))?;
    writeln!(out, "extrinsics: {}", origin(&a.extrinsics, "assets/extrinsics/table2.ron"))?;
    let qs: Vec<String> = robot
        .links
        .iter()
        .zip(&q_display)
        .map(|(l, v)| format!("{} = {v:.3} {}", l.name, l.joint.display_unit()))
        .collect();
    writeln!(out, "joints:     {}", qs.join(", "))?;
    writeln!(out)?;
    writeln!(out, "{:<28} {:>34}   rotation (rows; columns are the frame's axes)", "frame", "origin in world (µm)")?;
    for (i, n) in tree.nodes.iter().enumerate() {
        let p = n.world.translation.vector;
        let m = n.world.rotation.to_rotation_matrix().into_inner();
        let row = |r: usize| format!("{:+.6} {:+.6} {:+.6}", m[(r, 0)], m[(r, 1)], m[(r, 2)]);
        let name = format!("{}{}", "  ".repeat(tree.depth(i)), n.name);
        writeln!(
            out,
            "{name:<28} ({:>10.3}, {:>10.3}, {:>10.3})   [{}] [{}] [{}]",
            p.x,
            p.y,
            p.z,
            row(0),
            row(1),
            row(2)
        )?;
    }
    writeln!(out)?;
    match &tree.cavity {
        Ok(c) => {
            writeln!(out, "signed cavity length L = {:.3} µm (gap |L| = {:.3} µm)", c.length_um, c.length_um.abs())?;
            let (w, t) = (c.reflection_point_world_um, c.reflection_point_tool_um);
            writeln!(out, "reflection point P_r in world = ({:.3}, {:.3}, {:.3}) µm", w.x, w.y, w.z)?;
            writeln!(out, "reflection point P_r in tool  = ({:.3}, {:.3}, {:.3}) µm", t.x, t.y, t.z)?;
            writeln!(out, "optical axis n_f = ({:.6}, {:.6}, {:.6})", c.n_f.x, c.n_f.y, c.n_f.z)?;
            writeln!(out, "lamella normal n_t = ({:.6}, {:.6}, {:.6})", c.n_t.x, c.n_t.y, c.n_t.z)?;
            writeln!(
                out,
                "angle between n_t and n_f = {:.3} mrad ({:.4}°)",
                c.tilt_rad * 1e3,
                c.tilt_rad.to_degrees()
            )?;
        }
        Err(e) => writeln!(out, "no cavity: {e}")?,
    }
    Ok(())
}
