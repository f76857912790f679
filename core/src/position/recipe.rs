//! Assembly recipes: several targets in a row, from a small RON file. Owns the recipe format,
//! its checks (every target's field named on error) and where a recipe stands after the moves
//! a session recorded (the steps confirmed, the next one to run).
//!
//! ```text
//! Recipe(
//!     name: "glue lamella",
//!     steps: [
//!         (label: "approach", target: (gap_um: 950.0, tilt_deg: (0.0, 0.0))),
//!         (label: "place", target: (gap_um: 850.0, tilt_deg: (0.0, 0.0), lateral_um: (-20.0, 0.0)), keep_gap: true),
//!     ],
//! )
//! ```

use super::record::{MoveRecord, Verdict};
use super::target::Target;
use crate::files::{self, FieldError, FileError};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One step of a recipe.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecipeStep {
    /// What the step is for (shown and recorded).
    #[serde(default)]
    pub label: String,
    /// Where the lamella goes.
    pub target: Target,
    /// Hold the gap (the larger of start and end) while the rest moves.
    #[serde(default)]
    pub keep_gap: bool,
}

/// Targets run one after the other, each confirmed before the next.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Recipe {
    /// Its name (the moves of a session are matched to it by name).
    pub name: String,
    /// What it is for.
    #[serde(default)]
    pub description: String,
    /// The steps, in order.
    pub steps: Vec<RecipeStep>,
}

const EXPECTED: &str =
    "a Recipe(name, steps: [(label, target: (gap_um, tilt_deg, lateral_um, rotation_deg), keep_gap)])";

impl Recipe {
    /// Parse and check; `origin` names the text in errors.
    pub fn from_ron_str(text: &str, origin: &Path) -> Result<Self, FileError> {
        let r: Self = files::parse_ron(text, origin, EXPECTED)?;
        r.check().map_err(|f| f.in_file(origin))?;
        Ok(r)
    }

    /// Load and check a recipe file.
    pub fn load(path: &Path) -> Result<Self, FileError> {
        Self::from_ron_str(&files::read_text(path)?, path)
    }

    /// A name, at least one step, and every target a target.
    pub fn check(&self) -> Result<(), FieldError> {
        if self.name.trim().is_empty() {
            return Err(FieldError::new("name", "expected a name for the recipe, found an empty one"));
        }
        if self.steps.is_empty() {
            return Err(FieldError::new("steps", "expected at least one step, found none"));
        }
        for (i, s) in self.steps.iter().enumerate() {
            s.target.check().map_err(|e| {
                let (field, problem) = e.split_once(": ").unwrap_or(("", &e));
                FieldError::new(format!("steps[{i}].target.{field}"), problem.to_string())
            })?;
        }
        Ok(())
    }

    /// The first step not yet confirmed among `moves` (a session's history): the step to run
    /// next when the recipe is resumed; `steps.len()` when every step is confirmed. A step
    /// counts as confirmed when its last move is, to the same target.
    pub fn next_step(&self, moves: &[MoveRecord]) -> usize {
        (0..self.steps.len())
            .find(|&i| {
                let last = moves.iter().rev().find(|m| m.recipe.as_ref() == Some(&(self.name.clone(), i)));
                !last.is_some_and(|m| m.verdict == Verdict::Confirmed && m.requested == self.steps[i].target)
            })
            .unwrap_or(self.steps.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = r#"Recipe(
        name: "glue lamella",
        steps: [
            (label: "approach", target: (gap_um: 950.0, tilt_deg: (0.0, 0.0))),
            (label: "place", target: (gap_um: 850.0, tilt_deg: (0.5, 0.0), lateral_um: (-20.0, 0.0)), keep_gap: true),
        ],
    )"#;

    #[test]
    fn a_recipe_reads_and_a_bad_target_is_named() {
        let r = Recipe::from_ron_str(TEXT, Path::new("r.ron")).unwrap();
        assert_eq!(r.steps.len(), 2);
        assert!(r.steps[1].keep_gap && r.steps[1].target.lateral_um == [-20.0, 0.0]);
        let bad = TEXT.replace("gap_um: 850.0", "gap_um: -1.0");
        let e = Recipe::from_ron_str(&bad, Path::new("r.ron")).unwrap_err().to_string();
        assert!(e.starts_with("r.ron: field `steps[1].target.gap_um`:"), "{e}");
        let bad = TEXT.replace("tilt_deg: (0.0, 0.0))", "tilt: (0.0, 0.0))");
        let e = Recipe::from_ron_str(&bad, Path::new("r.ron")).unwrap_err().to_string();
        assert!(e.contains("r.ron") && e.contains("tilt"), "{e}");
    }
}
