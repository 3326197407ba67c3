//! `splatraj query`: what a semantic query selects in a scene, as text (or JSON) and as a
//! picture (`query.png`, the selection tinted). The scene and source come from the options or
//! from a run config (`--config RUN.toml`). The work is `splatraj::experiment::query`
//! ([`ConfigQuery`], [`QueryRequest`](splatraj::experiment::query::QueryRequest),
//! [`PictureOptions`]); `args.rs` parses the options, this file prints.

mod args;

use anyhow::{Context, Result, bail};
use splatraj::experiment::outputs::write_bytes;
use splatraj::experiment::query::{ConfigQuery, PictureOptions, QueryOutcome, SelectionFailed};
use splatraj::experiment::{Config, Extensions};
use splatraj_render::backend::BackendKind;
use splatraj_semantic::SourceRegistry;

use args::IMAGE_NAME;
pub use args::QueryArgs;

/// Runs `splatraj query`.
pub fn run(args: QueryArgs) -> Result<()> {
    // Cheap checks first, then the scene and the source, then the render; the file last.
    if args.query.trim().is_empty() {
        bail!("--query is empty: give a label name, a phrase or a region name");
    }
    let picture = args.picture()?;
    let outcome = match &args.config {
        Some(path) => {
            let extensions = Extensions::default();
            let config = Config::load_with(path, &args.set, &extensions)?;
            let query = ConfigQuery {
                query: args.query.clone(),
                picture,
                backend: args.backend,
            };
            query.run(&config, &extensions)
        }
        None => from_options(&args, picture),
    }
    .inspect_err(|e| {
        // Nothing selected: show why before the error.
        if let Some(failed) = e.downcast_ref::<SelectionFailed>() {
            match serde_json::to_string_pretty(&failed.explanation) {
                Ok(json) if args.json => println!("{json}"),
                _ => print!("{}", failed.explanation.text()),
            }
        }
    })?;

    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the output folder {}", args.out.display()))?;
    let path = args.out.join(IMAGE_NAME);
    write_bytes(&path, &outcome.png)?;
    let report = outcome.report(&path);
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.text());
    }
    eprintln!(
        "wrote {} ({}×{}, {:.1}% of the pixels highlighted)",
        path.display(),
        args.width,
        args.height,
        100.0 * outcome.highlighted_share
    );
    Ok(())
}

/// The query on the scene file of `--scene` with the built-in sources.
fn from_options(args: &QueryArgs, picture: PictureOptions) -> Result<QueryOutcome> {
    let request = args.request(picture)?;
    let device = args.backend.unwrap_or(BackendKind::Flex).device()?;
    let path = args
        .scene
        .as_deref()
        .context("--scene (or --config) is needed")?;
    let scene = args.read.load(path)?.scene;
    let name = path.display().to_string();
    request.run(&scene, &name, &SourceRegistry::default(), &device)
}
