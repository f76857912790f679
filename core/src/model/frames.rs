//! The frame tree of the bench: world → links 1..n → end effector → tool → reflection point, and world → fiber.
//! Owns the tree as plain data (names, parents, local and world poses) that the GUI draws and the CLI prints.

use crate::model::extrinsics::{Cavity, CavityError, Extrinsics};
use crate::model::kinematics::Chain;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use serde::Serialize;

/// What a frame stands for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FrameKind {
    /// The world (robot base) frame.
    World,
    /// The frame after joint i.
    Link,
    /// The end-effector frame (the last link's frame).
    EndEffector,
    /// The lamella (tool) frame.
    Tool,
    /// The fiber frame (optical axis = its Y axis).
    Fiber,
    /// The reflection point on the lamella (a point; its axes are the tool's).
    ReflectionPoint,
}

/// One node of the tree.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameNode {
    /// Display name, e.g. "link 3", "tool".
    pub name: String,
    /// Kind of frame.
    pub kind: FrameKind,
    /// Index of the parent node, `None` for the world.
    pub parent: Option<usize>,
    /// Pose in the parent frame (µm).
    pub local: Isometry3<f64>,
    /// Pose in the world (µm).
    pub world: Isometry3<f64>,
}

/// The whole tree at one robot pose, plus the cavity it defines.
#[derive(Debug, Clone)]
pub struct FrameTree {
    /// Nodes in parent-before-child order; node 0 is the world.
    pub nodes: Vec<FrameNode>,
    /// The cavity (L, P_r) at this pose, or why there is none.
    pub cavity: Result<Cavity, CavityError>,
}

impl FrameTree {
    /// Build the tree for joint vector `q` (internal units).
    pub fn new(chain: &Chain, extrinsics: &Extrinsics, q: &[f64]) -> Self {
        let mut nodes = vec![FrameNode {
            name: "world".into(),
            kind: FrameKind::World,
            parent: None,
            local: Isometry3::identity(),
            world: Isometry3::identity(),
        }];
        let push = |nodes: &mut Vec<FrameNode>, name: String, kind, parent: usize, local: Isometry3<f64>| {
            let world = nodes[parent].world * local;
            nodes.push(FrameNode { name, kind, parent: Some(parent), local, world });
            nodes.len() - 1
        };
        let mut parent = 0;
        for (i, qi) in q.iter().enumerate() {
            let name = format!("link {} ({})", i + 1, chain.description().links[i].name);
            parent = push(&mut nodes, name, FrameKind::Link, parent, chain.link_transform(i, *qi));
        }
        let ee = push(&mut nodes, "end effector".into(), FrameKind::EndEffector, parent, Isometry3::identity());
        let tool = push(&mut nodes, "tool (lamella)".into(), FrameKind::Tool, ee, extrinsics.ee_to_tool());
        let cavity = extrinsics.cavity(&nodes[ee].world);
        if let Ok(c) = &cavity {
            let local = Isometry3::from_parts(
                Translation3::from(c.reflection_point_tool_um.coords),
                UnitQuaternion::identity(),
            );
            push(&mut nodes, "reflection point P_r".into(), FrameKind::ReflectionPoint, tool, local);
        }
        // The fiber last, so a listing in tree order reads right (P_r under the tool).
        push(&mut nodes, "fiber".into(), FrameKind::Fiber, 0, extrinsics.world_to_fiber());
        Self { nodes, cavity }
    }

    /// Children of node `i`.
    pub fn children(&self, i: usize) -> impl Iterator<Item = usize> + '_ {
        self.nodes.iter().enumerate().filter(move |(_, n)| n.parent == Some(i)).map(|(k, _)| k)
    }

    /// Depth of node `i` (world = 0).
    pub fn depth(&self, i: usize) -> usize {
        let mut d = 0;
        let mut n = i;
        while let Some(p) = self.nodes[n].parent {
            d += 1;
            n = p;
        }
        d
    }

    /// The tree as serialisable records (positions in µm, rotations as row-major matrices).
    pub fn records(&self) -> Vec<FrameRecord> {
        self.nodes
            .iter()
            .map(|n| FrameRecord {
                name: n.name.clone(),
                kind: n.kind,
                parent: n.parent.map(|p| self.nodes[p].name.clone()),
                position_um: point(&n.world.translation.vector.into()),
                rotation: rows(&n.world.rotation),
                local_position_um: point(&n.local.translation.vector.into()),
                local_rotation: rows(&n.local.rotation),
            })
            .collect()
    }
}

fn point(p: &Point3<f64>) -> [f64; 3] {
    [p.x, p.y, p.z]
}

fn rows(q: &UnitQuaternion<f64>) -> [[f64; 3]; 3] {
    let m = q.to_rotation_matrix().into_inner();
    [0, 1, 2].map(|r| [m[(r, 0)], m[(r, 1)], m[(r, 2)]])
}

/// A frame as printed by the CLI (`--json`) and listed by the GUI.
#[derive(Debug, Clone, Serialize)]
pub struct FrameRecord {
    /// Display name.
    pub name: String,
    /// Kind of frame.
    pub kind: FrameKind,
    /// Parent's name.
    pub parent: Option<String>,
    /// Origin in the world (µm).
    pub position_um: [f64; 3],
    /// Rotation in the world, row-major (its columns are the frame's axes).
    pub rotation: [[f64; 3]; 3],
    /// Origin in the parent frame (µm).
    pub local_position_um: [f64; 3],
    /// Rotation in the parent frame, row-major.
    pub local_rotation: [[f64; 3]; 3],
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::robot::RobotDescription;
    use proptest::prelude::*;

    #[test]
    fn tree_has_every_frame_in_order() {
        let t = FrameTree::new(&Chain::femto_6dof(), &Extrinsics::table2(), &[0.0; 6]);
        let names: Vec<&str> = t.nodes.iter().map(|n| n.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "world",
                "link 1 (q1)",
                "link 2 (q2)",
                "link 3 (q3)",
                "link 4 (q4)",
                "link 5 (q5)",
                "link 6 (q6)",
                "end effector",
                "tool (lamella)",
                "reflection point P_r",
                "fiber"
            ]
        );
        assert_eq!(t.children(0).count(), 2, "world has link 1 and the fiber as children");
        assert_eq!(t.depth(9), 9);
        let pr = t.nodes[9].world.translation.vector;
        let c = t.cavity.unwrap();
        assert!((pr - c.reflection_point_world_um.coords).norm() < 1e-9);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        #[test]
        fn world_poses_compose_along_the_tree(
            qd in proptest::collection::vec(-1.0..1.0f64, 6),
        ) {
            let scale = [150.0, 150.0, 150.0, 10.0, 10.0, 180.0];
            let qd: Vec<f64> = qd.iter().zip(scale).map(|(a, s)| a * s).collect();
            let chain = Chain::femto_6dof();
            let q = RobotDescription::femto_6dof().q_from_display(&qd);
            let e = Extrinsics::table2();
            let t = FrameTree::new(&chain, &e, &q);
            for n in &t.nodes {
                let want = match n.parent { Some(p) => t.nodes[p].world * n.local, None => n.local };
                prop_assert!((want.translation.vector - n.world.translation.vector).norm() < 1e-9);
                prop_assert!(want.rotation.angle_to(&n.world.rotation) < 1e-12);
            }
            // The link chain ends at the DGM; the tool at DGM·eTt; the fiber at wTf.
            let ee = chain.end_effector(&q);
            prop_assert!((t.nodes[7].world.translation.vector - ee.translation.vector).norm() < 1e-9);
            let tool = ee * e.ee_to_tool();
            prop_assert!(t.nodes[8].world.rotation.angle_to(&tool.rotation) < 1e-12);
            prop_assert!((t.nodes[10].world.translation.vector - e.world_to_fiber().translation.vector).norm() < 1e-12);
            // The reflection point lies on the beam and on the lamella plane.
            let c = t.cavity.unwrap();
            let pr = t.nodes[9].world.translation.vector;
            let on_beam = e.world_to_fiber().translation.vector + c.n_f.into_inner() * c.length_um;
            prop_assert!((pr - on_beam).norm() < 1e-9);
        }
    }
}
