//! The virtual bench seen through the hardware abstraction: [`VirtualStages`] drives a
//! [`VirtualBench`] as one six-axis [`StageController`] with a [`DataRecorder`], so that code written
//! for real controllers runs unchanged on the simulation.
//!
//! Moves are run to completion in bench time when commanded (the virtual bench simulates a whole
//! segment at once): `on_target` is then always true. While the recorder is armed, every move is
//! recorded and its samples appended.

use super::{AxisInfo, DataRecorder, HwError, RecordedBlock, RecorderRequest, RecorderSetup, StageController};
use crate::bench::{AxisUnit, Bench, RunControl, VirtualBench};
use crate::model::robot::JointType;
use crate::plan::{JointTarget, Plan, Segment};
use crate::trace::{Trace, TraceMeta};
use std::sync::atomic::AtomicBool;

/// A virtual bench as a six-axis stage controller.
pub struct VirtualStages {
    bench: VirtualBench,
    axes: Vec<AxisInfo>,
    recording: Option<Trace>,
    recorded_axes: Vec<usize>,
    recorded_inputs: usize,
}

impl VirtualStages {
    /// Wrap a virtual bench; axis i is joint q(i+1), in µm or °.
    pub fn new(bench: VirtualBench) -> Self {
        let axes = bench
            .robot()
            .links
            .iter()
            .map(|l| AxisInfo {
                id: l.name.clone(),
                unit: match l.joint {
                    JointType::Prismatic => AxisUnit::Micrometre,
                    JointType::Revolute => AxisUnit::Degree,
                },
            })
            .collect();
        VirtualStages { bench, axes, recording: None, recorded_axes: vec![], recorded_inputs: 0 }
    }

    /// The wrapped bench.
    pub fn bench(&self) -> &VirtualBench {
        &self.bench
    }

    fn usage(&self, problem: String) -> HwError {
        HwError::Usage { controller: self.name(), problem }
    }

    fn run_move(&mut self, target: [f64; 6]) -> Result<(), HwError> {
        let record = self.recording.is_some();
        let plan = Plan {
            name: "virtual stages".into(),
            description: String::new(),
            segments: vec![Segment::Move {
                to: JointTarget::all(target),
                record,
                label: "move".into(),
                through: false,
            }],
        };
        let segments = plan
            .expand(self.bench.robot(), self.bench.position_display(), self.bench.motion_limits())
            .map_err(|e| self.usage(e.to_string()))?;
        let cancel = AtomicBool::new(false);
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        let trace = self
            .bench
            .run_segment(&segments[0], TraceMeta::default(), &mut control)
            .map_err(|e| self.usage(e.to_string()))?;
        if let (Some(rec), Some(t)) = (self.recording.as_mut(), trace) {
            for i in 0..t.len() {
                rec.push_sample(t.t_s[i], t.joints_display(i), t.wavelength_nm[i], t.irradiance[i]);
            }
        }
        Ok(())
    }

    fn check(&self, axis: usize) -> Result<(), HwError> {
        if axis < 6 {
            Ok(())
        } else {
            Err(self.usage(format!("no axis with index {axis} (the virtual bench has 6)")))
        }
    }
}

impl StageController for VirtualStages {
    fn name(&self) -> String {
        self.bench.name()
    }

    fn axes(&self) -> &[AxisInfo] {
        &self.axes
    }

    fn move_absolute(&mut self, targets: &[(usize, f64)]) -> Result<(), HwError> {
        let mut q = self.bench.position_display();
        for &(a, t) in targets {
            self.check(a)?;
            let (min, max) = self.travel_limits(a)?;
            if !(t.is_finite() && t >= min && t <= max) {
                return Err(HwError::OutOfRange {
                    controller: self.name(),
                    axis: self.axes[a].id.clone(),
                    target: t,
                    min,
                    max,
                    unit: self.axes[a].unit.symbol(),
                });
            }
            q[a] = t;
        }
        self.run_move(q)
    }

    fn move_relative(&mut self, steps: &[(usize, f64)]) -> Result<(), HwError> {
        let q = self.bench.position_display();
        let targets: Vec<(usize, f64)> =
            steps.iter().map(|&(a, d)| (a, q.get(a).copied().unwrap_or(0.0) + d)).collect();
        self.move_absolute(&targets)
    }

    fn positions(&mut self, axes: &[usize]) -> Result<Vec<f64>, HwError> {
        let q = self.bench.position_display();
        axes.iter().map(|&a| self.check(a).map(|()| q[a])).collect()
    }

    fn on_target(&mut self, axes: &[usize]) -> Result<Vec<bool>, HwError> {
        axes.iter().map(|&a| self.check(a).map(|()| true)).collect()
    }

    fn stop(&mut self) -> Result<(), HwError> {
        Ok(())
    }

    fn set_velocity(&mut self, axis: usize, _per_s: f64) -> Result<(), HwError> {
        self.check(axis)
    }

    fn travel_limits(&mut self, axis: usize) -> Result<(f64, f64), HwError> {
        self.check(axis)?;
        let l = self.bench.robot().links[axis].limits;
        Ok((l.min, l.max))
    }

    fn is_referenced(&mut self, axis: usize) -> Result<bool, HwError> {
        self.check(axis).map(|()| true)
    }

    fn reference(&mut self, axis: usize) -> Result<(), HwError> {
        self.check(axis)
    }

    fn reconnect(&mut self) -> Result<(), HwError> {
        Ok(())
    }

    fn recorder(&mut self) -> Option<&mut dyn DataRecorder> {
        Some(self)
    }
}

impl DataRecorder for VirtualStages {
    /// The virtual bench samples at its preset's rate, whatever is asked.
    /// Inputs: the first is the photodiode, any other the laser wavelength (nm).
    fn arm(&mut self, request: &RecorderRequest) -> Result<RecorderSetup, HwError> {
        for &a in &request.axes {
            self.check(a)?;
        }
        self.recorded_axes = request.axes.clone();
        self.recorded_inputs = request.inputs.len();
        self.recording = Some(Trace::new(TraceMeta::default()));
        Ok(RecorderSetup { sample_period_s: self.bench.sample_period_s(), capacity: None })
    }

    fn recorded_len(&mut self) -> Result<usize, HwError> {
        Ok(self.recording.as_ref().map_or(0, Trace::len))
    }

    fn read(&mut self, start: usize, count: usize) -> Result<RecordedBlock, HwError> {
        let Some(t) = self.recording.as_ref() else {
            return Err(self.usage("the recorder is not armed".into()));
        };
        if start + count > t.len() {
            return Err(self.usage(format!("asked for samples {start}..{} of {}", start + count, t.len())));
        }
        let r = start..start + count;
        Ok(RecordedBlock {
            start,
            axes: self.recorded_axes.iter().map(|&a| t.joint_column(a)[r.clone()].to_vec()).collect(),
            inputs: (0..self.recorded_inputs)
                .map(|k| if k == 0 { t.irradiance[r.clone()].to_vec() } else { t.wavelength_nm[r.clone()].to_vec() })
                .collect(),
        })
    }

    fn read_input(&mut self, _input: &str) -> Result<f64, HwError> {
        let q = self.bench.position_display();
        self.bench.reflected_power_mw(self.bench.clock_s(), &q, self.bench.wavelength_nm()).map_err(|e| self.usage(e))
    }
}
