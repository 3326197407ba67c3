//! `splatraj query`: what a semantic query selects in a scene, as text (or JSON) and as a
//! picture (`query.png`, the selection tinted). The scene and source come from the options or
//! from a run config (`--config RUN.toml`). The work is `splatraj::experiment::query`
//! ([`ConfigQuery`], [`QueryRequest`](splatraj::experiment::query::QueryRequest),
//! [`PictureOptions`]); `args.rs` parses the options, this file prints.

mod args;

use anyhow::{Context, Result, bail};
use splatraj::experiment::outputs::write_bytes;
use splatraj::experiment::query::{
    ConfigQuery, PictureOptions, QueryOutcome, QueryReport, SelectionFailed, config_query_texts,
};
use splatraj::experiment::{Config, Extensions};
use splatraj_render::backend::BackendKind;
use splatraj_semantic::SourceRegistry;

use args::IMAGE_NAME;
pub use args::QueryArgs;

/// Runs `splatraj query`.
pub fn run(args: QueryArgs) -> Result<()> {
    // Cheap checks first, then the scene and the source, then the render; the files last.
    if args.query.as_ref().is_some_and(|q| q.trim().is_empty()) {
        bail!("--query is empty: give a label name, a phrase or a region name");
    }
    let picture = args.picture()?;
    let Some(path) = &args.config else {
        let report = show(&args, from_options(&args, picture), IMAGE_NAME)?;
        return print_report(&args, &report);
    };
    let extensions = Extensions::default();
    let config = Config::load_with(path, &args.set, &extensions)?;
    let texts = match &args.query {
        Some(query) => vec![query.clone()],
        None => config_query_texts(&config),
    };
    if texts.is_empty() {
        bail!(
            "config {}: no query to check (every [[queries]] uses a mask file); give --query",
            path.display()
        );
    }
    let prepared = ConfigQuery {
        picture,
        backend: args.backend,
    }
    .prepare(&config, &extensions)?;
    if args.query.is_some() {
        let report = show(&args, prepared.find(&texts[0]), IMAGE_NAME)?;
        return print_report(&args, &report);
    }
    // Every query of the config, each with its own picture; JSON as one array.
    let mut reports = Vec::with_capacity(texts.len());
    for (i, text) in texts.iter().enumerate() {
        if !args.json {
            println!("== query {} of {}: {text}", i + 1, texts.len());
        }
        let report = show(&args, prepared.find(text), &format!("query-{}.png", i + 1))
            .with_context(|| format!("query {} ({text:?})", i + 1))?;
        if !args.json {
            print!("{}", report.text());
        }
        reports.push(report);
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&reports)?);
    }
    Ok(())
}

/// Prints why nothing was selected when that is the error, else writes the picture as
/// `image_name` into `--out` and returns the report.
fn show(args: &QueryArgs, outcome: Result<QueryOutcome>, image_name: &str) -> Result<QueryReport> {
    let outcome = outcome.inspect_err(|e| {
        if let Some(failed) = e.downcast_ref::<SelectionFailed>() {
            match serde_json::to_string_pretty(&failed.explanation) {
                Ok(json) if args.json => println!("{json}"),
                _ => print!("{}", failed.explanation.text()),
            }
        }
    })?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the output folder {}", args.out.display()))?;
    let path = args.out.join(image_name);
    write_bytes(&path, &outcome.png)?;
    let report = outcome.report(&path);
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    eprintln!(
        "wrote {} ({}×{}, {:.1}% of the pixels highlighted)",
        path.display(),
        args.width,
        args.height,
        100.0 * outcome.highlighted_share
    );
    Ok(report)
}

/// One query's report, as text or JSON.
fn print_report(args: &QueryArgs, report: &QueryReport) -> Result<()> {
    if args.json {
        println!("{}", serde_json::to_string_pretty(report)?);
    } else {
        print!("{}", report.text());
    }
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
