//! Debug: the view search's best candidates per window, with seen/alone mask PNGs.
use std::path::Path;

use splatraj::experiment::{Config, Experiment};
use splatraj::render::camera::Pose;
use splatraj::render::host::{OnDevice, to_host};
use splatraj::render::images::png_gray;
use splatraj::render::render::{Channel, Pruning, RenderRequest, render};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let config = Config::load(Path::new(&args[1]), &args[2..])?;
    let e = Experiment::prepare(&config)?;
    let views = e.measured_views(&(0..e.windows.len()).collect::<Vec<_>>())?;
    let scene = e.plain_scene();
    for (i, w) in views.iter().enumerate() {
        let mut order: Vec<usize> = (0..w.candidates.len()).collect();
        order.sort_by(|&a, &b| w.candidates[b].visible_share.total_cmp(&w.candidates[a].visible_share));
        println!("window {i} {:?}: radius {:.3}", e.windows[i].name, w.radius);
        for &k in order.iter().take(5) {
            let c = &w.candidates[k];
            println!("  az {:6.1} el {:5.1} d {:.3} visible {:.3} coverage {:.3} clearance {:?} inside {}", c.azimuth_degrees, c.elevation_degrees, c.distance, c.visible_share, c.coverage, c.clearance, c.inside_object);
        }
        let best = &w.candidates[order[0]];
        let k = e.intrinsics.rescaled(256, 144)?;
        let alone = e.object_alone(i);
        for (name, s, mask) in [("seen", &scene, e.windows[i].mask.clone()), ("alone", &alone, vec![1.0; alone.len()])] {
            let request = RenderRequest { pruning: Pruning::ObjectOnly, ..RenderRequest::new(k, vec![Channel::Mask(mask)]) };
            let img = to_host(render(s, s.poses(&[Pose(best.pose)]), &request)?.images)?;
            std::fs::write(format!("/tmp/view_{i}_{name}.png"), png_gray(&img, &k)?)?;
            let sum: f64 = img.iter().sum();
            println!("  best {name}: sum {sum:.1}, max {:.3}", img.iter().cloned().fold(0.0, f64::max));
        }
    }
    Ok(())
}
