// TEMPORARY (demo-scene agent): renders the demo scene from a few viewpoints. Deleted after use.
use splatraj_render::reference::{RefCamera, RefChannels, render_reference};
use splatraj_scene::demo::{DemoConfig, demo_scene};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let out = std::path::PathBuf::from(&args[1]);
    let n: usize = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(100_000);
    let seed: u64 = args.get(3).map(|s| s.parse().unwrap()).unwrap_or(7);
    let t = std::time::Instant::now();
    let scene = demo_scene(&DemoConfig { seed, gaussians: n }).unwrap();
    eprintln!("generated {} in {:?}", scene.len(), t.elapsed());
    let views: [(&str, [f64; 3], [f64; 3], f64); 7] = [
        ("plant", [1.75, 0.0, 0.75], [1.15, 0.75, 0.2], 55.0),
        ("back", [0.1, 1.3, 1.15], [-0.1, 0.0, 0.8], 60.0),
        ("overview", [-0.3, -1.8, 1.2], [0.0, 0.1, 0.8], 60.0),
        ("corner", [1.9, -1.95, 2.2], [-0.2, 0.4, 0.6], 70.0),
        ("close", [0.55, -0.75, 1.05], [0.05, 0.1, 0.82], 55.0),
        ("side", [1.9, -0.3, 0.95], [0.2, 0.3, 0.6], 60.0),
        ("low", [-1.0, -1.2, 0.85], [0.0, 0.2, 0.85], 50.0),
    ];
    let (w, h) = (800usize, 600usize);
    for (name, eye, target, fov) in views {
        if let Some(only) = args.get(4) {
            if only != name {
                continue;
            }
        }
        let f = 0.5 * w as f64 / (0.5 * fov as f64).to_radians().tan();
        let cam = RefCamera::look_at(
            eye,
            target,
            [0.0, 0.0, 1.0],
            f,
            f,
            w as f64 / 2.0,
            h as f64 / 2.0,
            w,
            h,
        );
        let t = std::time::Instant::now();
        let img = render_reference(
            &scene,
            &cam,
            &RefChannels {
                rgb: true,
                ..Default::default()
            },
        );
        img.save_png(out.join(format!("{name}.png"))).unwrap();
        let a: Vec<u8> = img
            .alpha
            .iter()
            .map(|a| (a * 255.0).round() as u8)
            .collect();
        image::save_buffer(
            out.join(format!("{name}_alpha.png")),
            &a,
            w as u32,
            h as u32,
            image::ExtendedColorType::L8,
        )
        .unwrap();
        let mut hist = [0usize; 5];
        for a in &img.alpha {
            let k = if *a > 0.999 {
                4
            } else if *a > 0.99 {
                3
            } else if *a > 0.95 {
                2
            } else if *a > 0.8 {
                1
            } else {
                0
            };
            hist[k] += 1;
        }
        eprintln!("alpha hist (<.8, .8-.95, .95-.99, .99-.999, >.999): {hist:?}");
        eprintln!("{name} in {:?}", t.elapsed());
    }
}
