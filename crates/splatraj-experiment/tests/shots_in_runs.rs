//! Shots and planned starts from a config: a group window's target is the union of its
//! objects (the labels' masks merged, the box holding both), every window of the evaluation
//! reports occlusion and a shot window its adherence, a planned route needs the clearance
//! cost, and a planned start on the demo room (8 RBF centres per window, so the fit can
//! follow the route) keeps the margin where the straight one does not.

use std::path::Path;

use glam::DVec3;
use splatraj_experiment::{Config, Experiment, Extensions, optimise::observer};
use splatraj_traj::clearance::Occupancy;
use splatraj_traj::costs::ClearanceCost;

const ROOM: &str = r#"
name = "shots"
seed = 3
[scene]
demo = { gaussians = 20000, seed = 7 }
[[queries]]
text = "mug and ball"
shot = { kind = "group", objects = ["red mug", "green ball"] }
[[queries]]
text = "plant"
shot = { kind = "reveal", pan = 80 }
[camera]
width = 32
height = 24
# The box's working distances, as the planned-route case below was measured with.
working_distance = "box"
[costs.tce]
[costs.tre]
[costs.prior]
[costs.clearance]
weight = 30.0
margin = 0.1
[optimiser]
iterations = 2
samples_per_window = 2
[output]
width = 40
height = 30
metric_samples = 4
ldj_samples = 101
"#;

fn config(text: &str, sets: &[(&str, &str)]) -> anyhow::Result<Config> {
    let mut value: toml::Table = toml::from_str(text).unwrap();
    for (table, line) in sets {
        let patch: toml::Table = toml::from_str(line).unwrap();
        let target = value
            .entry(table.to_string())
            .or_insert_with(|| toml::Value::Table(Default::default()))
            .as_table_mut()
            .unwrap();
        target.extend(patch);
    }
    Config::from_toml(
        &toml::to_string(&value).unwrap(),
        Path::new("."),
        &Extensions::default(),
    )
}

#[test]
fn a_group_targets_the_union_and_the_evaluation_reports_shots_and_occlusion() {
    let experiment = Experiment::prepare(&config(ROOM, &[]).unwrap()).unwrap();
    let labels = |name: &str| {
        let single = config(
            &ROOM.replace("text = \"mug and ball\"\nshot = { kind = \"group\", objects = [\"red mug\", \"green ball\"] }", &format!("text = \"{name}\"")),
            &[],
        )
        .unwrap();
        let prepared = Experiment::prepare(&single).unwrap();
        prepared.windows[0].clone()
    };
    let (mug, ball) = (labels("red mug"), labels("green ball"));
    let group = &experiment.windows[0];
    for (i, &m) in group.mask.iter().enumerate() {
        assert_eq!(m, mug.mask[i].max(ball.mask[i]), "Gaussian {i}");
    }
    // The union's centre lies between the two objects' (the box holding both boxes).
    let (a, b, c) = (
        DVec3::from(mug.context.object_centre),
        DVec3::from(ball.context.object_centre),
        DVec3::from(group.context.object_centre),
    );
    assert!(c.distance(a) < a.distance(b) && c.distance(b) < a.distance(b));
    assert!(group.context.prior_radius > mug.context.prior_radius.max(ball.context.prior_radius));

    let run = experiment.run_trajectory(&mut observer::quiet()).unwrap();
    let trajectory = experiment.trajectory(&run.best().best).unwrap();
    let evaluation = experiment.evaluate(&trajectory).unwrap();
    let kinds: Vec<_> = evaluation
        .windows
        .iter()
        .map(|w| w.shot.as_ref().map(|s| s.kind))
        .collect();
    assert_eq!(kinds, [Some("group"), Some("reveal")]);
    for w in &evaluation.windows {
        let o = &w.occlusion;
        assert!(
            (0.0..=1.0).contains(&o.longest_hidden)
                && o.longest_hidden <= o.hidden_fraction + 1e-12
        );
    }
    let json = serde_json::to_value(&evaluation.windows).unwrap();
    assert!(
        json[1]["shot"]["aim"]["max"].is_number()
            && json[0]["occlusion"]["longest_hidden"].is_number()
    );
}

#[test]
fn a_planned_route_needs_the_clearance_cost() {
    let without = ROOM.replace("[costs.clearance]\nweight = 30.0\nmargin = 0.1\n", "");
    let err = config(&without, &[("start", "route = \"planned\"")]).unwrap_err();
    assert!(format!("{err:#}").contains("start.route"), "{err:#}");
    // `auto` without clearance goes straight; a typo is refused.
    assert!(config(&without, &[("start", "route = \"auto\"")]).is_ok());
    assert!(config(ROOM, &[("start", "route = \"around\"")]).is_err());
}

/// The smallest clearance of a start trajectory's camera centres, sampled finely.
fn start_clearance(experiment: &Experiment) -> f64 {
    let start = &experiment.start_trajectories().unwrap()[0];
    let trajectory = experiment.trajectory(start).unwrap();
    let clearance: &ClearanceCost = experiment.config.costs.clearance.as_ref().unwrap();
    let occupancy = Occupancy::new(
        &experiment.scene,
        splatraj_traj::clearance::OccupancySpec {
            sigma: clearance.sigma,
            min_opacity: clearance.min_opacity,
        },
    );
    let times: Vec<f64> = (0..=2000).map(|k| k as f64 / 2000.0).collect();
    let centres: Vec<DVec3> = trajectory
        .poses_at(&times)
        .iter()
        .map(|p| DVec3::new(p[3], p[4], p[5]))
        .collect();
    occupancy
        .clearances(&centres, clearance.margin().unwrap())
        .into_iter()
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn the_demo_rooms_planned_start_keeps_clearer_than_the_straight_one() {
    let plain = ROOM
        .replace(
            "shot = { kind = \"group\", objects = [\"red mug\", \"green ball\"] }",
            "",
        )
        .replace("text = \"mug and ball\"", "text = \"green ball\"")
        .replace("shot = { kind = \"reveal\", pan = 80 }", "");
    let closest = |route: &str| {
        let config = config(
            &plain,
            &[
                ("start", &format!("route = \"{route}\"\nkind = \"objects\"")),
                ("trajectory", "kind = \"rbf\"\ncentres_per_window = 8"),
            ],
        )
        .unwrap();
        start_clearance(&Experiment::prepare(&config).unwrap())
    };
    let (straight, planned) = (closest("straight"), closest("planned"));
    println!("start's smallest clearance: straight {straight:.4}, planned {planned:.4}");
    // Measured: the straight start passes 5 mm inside the geometry between the ball and the
    // plant; the planned one keeps 12 cm.
    assert!(
        straight < 0.1,
        "the straight start kept the margin ({straight})"
    );
    assert!(
        planned >= 0.1,
        "the planned start comes {planned} from the geometry"
    );
}

/// The demo room with one window on the plant whose `[[queries]]` table ends with `extra`.
fn plant_holding(extra: &str) -> anyhow::Result<Config> {
    let text = format!(
        r#"
name = "hold"
[scene]
demo = {{ gaussians = 20000, seed = 7 }}
[[queries]]
text = "red mug"
[[queries]]
text = "plant"
{extra}
[camera]
width = 32
height = 24
[output]
seconds = 9.0
"#
    );
    Config::from_toml(&text, Path::new("."), &Extensions::default())
}

#[test]
fn a_hold_names_a_shot_preset_that_breathes() {
    // Issue 37: `hold = "still" | "orbit" | "push"`, holds a viewer can follow: a slow orbit
    // of a few degrees a second, a slow push-in, or one framing. Each window here is 4.5 s.
    let window_seconds = 4.5;
    let shot_of = |hold: &str| {
        let config = plant_holding(&format!("hold = \"{hold}\"")).unwrap();
        let experiment = Experiment::prepare(&config).unwrap();
        let shots = experiment.shot_paths().unwrap();
        assert!(shots[0].is_none(), "the mug's window holds still");
        shots[1]
    };
    assert_eq!(shot_of("still"), None);
    let orbit = shot_of("orbit").expect("an orbit");
    assert_eq!(orbit.kind, "orbit");
    let degrees_per_second = orbit.turn.abs().to_degrees() / window_seconds;
    assert!(
        degrees_per_second > 1.0 && degrees_per_second <= 10.0,
        "a slow orbit: {degrees_per_second}°/s"
    );
    assert_eq!(orbit.radius.0, orbit.radius.1, "it keeps its distance");
    let push = shot_of("push").expect("a push-in");
    assert_eq!(push.kind, "dolly");
    assert!(
        push.radius.0 > push.radius.1 && push.radius.1 > 0.0,
        "it moves in: {:?}",
        push.radius
    );
    assert_eq!(push.turn, 0.0, "along one view line");

    // Both say what the window does: refused, naming the keys.
    let both = format!(
        "{:#}",
        plant_holding("hold = \"orbit\"\nshot = { kind = \"dolly\" }").unwrap_err()
    );
    assert!(
        both.contains("queries.1.hold") && both.contains("queries.1.shot"),
        "{both}"
    );
    // An unknown hold names the key and the choices.
    let unknown = format!("{:#}", plant_holding("hold = \"spin\"").unwrap_err());
    assert!(
        unknown.contains("hold") && unknown.contains("orbit") && unknown.contains("push"),
        "{unknown}"
    );
}
