//! Scene loading speed on real files: `cargo bench -p splatraj-scene --bench load_scene`.
//!
//! Reads each file whole (decode + validation), as `splatraj` does. Files come from
//! `$SPLATRAJ_DATA` (default `shared/data` beside the repository) and the repository's fixtures; missing ones are
//! reported and left out.

use std::path::PathBuf;

use criterion::{Criterion, criterion_group, criterion_main};
use splatraj_scene::{ReadOptions, read_scene};

fn data_file(name: &str) -> Option<PathBuf> {
    let shared = std::env::var_os("SPLATRAJ_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"));
    let fixtures = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let found = [shared.join(name), fixtures.join(name)]
        .into_iter()
        .find(|p| p.exists());
    if found.is_none() {
        eprintln!("left out: {name} (not found; set SPLATRAJ_DATA)");
    }
    found
}

fn load(c: &mut Criterion) {
    let mut group = c.benchmark_group("load_scene");
    group.sample_size(10);
    for name in [
        "biker.compressed.ply",
        "biker.spz",
        "guitar.compressed.ply",
        "donut_fused.ply",
        "fruit_drops_minimal.ply",
    ] {
        let Some(path) = data_file(name) else {
            continue;
        };
        group.bench_function(name, |b| {
            b.iter(|| read_scene(&path, &ReadOptions::default()).expect("readable scene"))
        });
    }
    group.finish();
}

criterion_group!(benches, load);
criterion_main!(benches);
