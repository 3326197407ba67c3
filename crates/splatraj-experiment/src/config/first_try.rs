//! The first-try `[costs]` and `[trajectory]` as a config would write them: what `--set
//! costs.motion.weight=0` or `--set trajectory.centres_per_window=6` edits when the config
//! leaves those tables out. Written as TOML text, so that an override edits them as it edits
//! the file's own tables, and no typed value is turned back into TOML to be read again. The
//! typed defaults a config without the tables gets ([`CostsConfig::first_try`],
//! [`super::first_try_model`]) are the same values; a test holds the two together.

#[cfg(doc)]
use splatraj_traj::costs::CostsConfig;

/// The first-try costs as the `[costs]` table: the paper's four (upright about the horizon
/// only), clearance, the motion limits (speed `"auto"`, turning and circling at most 36°/s:
/// `splatraj_traj::costs::motion::FIRST_TRY_MAX_ANGULAR_SPEED`, `FIRST_TRY_MAX_ORBIT_SPEED`)
/// and visibility.
pub const FIRST_TRY_COSTS: &str = r#"
tce = {}
tre = {}
upright = { mode = "roll" }
prior = {}
clearance = { weight = 30.0 }
motion = { max_speed = "auto", max_angular_speed = 36.0, max_orbit_speed = 36.0 }
visibility = {}
"#;

/// The first-try trajectory model as the `[trajectory]` table: RBF with
/// [`super::FIRST_TRY_CENTRES_PER_WINDOW`] centres per window, a partition of unity.
pub const FIRST_TRY_TRAJECTORY: &str = r#"
kind = "rbf"
centres_per_window = 4
normalisation = "partition-of-unity"
"#;

/// `text` (one of the constants above) as a TOML table.
pub fn first_try_table(text: &str) -> toml::Table {
    toml::from_str(text).expect("the first-try tables are valid TOML")
}

#[cfg(test)]
mod tests {
    use splatraj_traj::costs::CostsConfig;
    use splatraj_traj::trajectory::TrajectoryModel;

    use super::*;

    #[test]
    fn the_tables_read_as_the_typed_first_try_defaults() {
        // Change both places together: the typed defaults a config without the tables gets,
        // and these tables an override edits.
        let costs: CostsConfig = first_try_table(FIRST_TRY_COSTS).try_into().unwrap();
        assert_eq!(costs, CostsConfig::first_try());
        let model: TrajectoryModel = first_try_table(FIRST_TRY_TRAJECTORY).try_into().unwrap();
        assert_eq!(model, super::super::first_try_model());
    }
}
