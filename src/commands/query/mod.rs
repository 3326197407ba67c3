//! `splatraj query`: what a semantic query selects in a scene, as text (or JSON) and as a
//! picture (`query.png`, the selection tinted). The scene and source come from a run config
//! (`--config RUN.toml`, whose keys the options given override) or from the options, which
//! make a config of their own (`args.rs` reads them into the library's typed
//! `QueryOptions`, whose one `config` makes either). The work is
//! `splatraj::experiment::picking` ([`ConfigQuery`], [`PictureOptions`]); this file prints.

mod args;
#[cfg(test)]
mod flags_match_file;

use anyhow::{Result, bail};
use splatraj::experiment::Extensions;
use splatraj::experiment::picking::query::{
    ConfigQuery, KeyNaming, PictureOptions, QueryOutcome, QueryReport, SelectionFailed,
    SourceChoice, config_query_texts,
};
use splatraj::experiment::write::write_into_folder;

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
        return show_one(&args, from_options(&args, picture));
    };
    let extensions = Extensions::default();
    // Low to high: the file, the options given, --set.
    let config = args.options()?.config(Some(path), &args.set, &extensions)?;
    let texts = config_query_texts(&config);
    let query = args.query_text();
    if query.is_none() && texts.is_empty() {
        bail!(
            "config {}: no query to check (every [[queries]] uses a mask file); give --query",
            path.display()
        );
    }
    let prepared = ConfigQuery {
        picture,
        backend: args.backend,
        source: SourceChoice::Configured,
        naming: KeyNaming::Config,
    }
    .prepare(&config, &extensions)?;
    if let Some(query) = &query {
        return show_one(&args, prepared.find(query));
    }
    // Every query of the config, each with its own picture; one failing does not stop the
    // others. JSON: one array of {key, report} or {key, query, error, explanation}.
    let mut entries = Vec::with_capacity(texts.len());
    let mut failed = Vec::new();
    for item in &texts {
        let key = item.key();
        if !args.json {
            println!("== {key}: {}", item.text);
        }
        let picture = match item.object {
            None => format!("query-{}.png", item.window + 1),
            Some(j) => format!("query-{}-{}.png", item.window + 1, j + 1),
        };
        match prepared
            .find(&item.text)
            .and_then(|outcome| write_picture(&args, &outcome, &picture))
        {
            Ok(report) => {
                if !args.json {
                    print!("{}", report.text());
                }
                entries.push(serde_json::json!({ "key": key, "report": report }));
            }
            Err(error) => {
                let explanation = error
                    .downcast_ref::<SelectionFailed>()
                    .map(|failed| &failed.explanation);
                if !args.json {
                    if let Some(explanation) = explanation {
                        print!("{}", explanation.text());
                    }
                    println!("failed: {error:#}");
                }
                entries.push(serde_json::json!({
                    "key": key,
                    "query": item.text,
                    "error": format!("{error:#}"),
                    "explanation": explanation,
                }));
                failed.push(format!("{key} ({:?})", item.text));
            }
        }
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&entries)?);
    }
    if !failed.is_empty() {
        bail!(
            "config {}: {} of {} queries failed: {}",
            path.display(),
            failed.len(),
            texts.len(),
            failed.join(", ")
        );
    }
    Ok(())
}

/// One query: why nothing was selected when that is the error, else the picture
/// (`query.png` in `--out`) and the report, as text or JSON.
fn show_one(args: &QueryArgs, outcome: Result<QueryOutcome>) -> Result<()> {
    let outcome = outcome.inspect_err(|e| {
        if let Some(failed) = e.downcast_ref::<SelectionFailed>() {
            match serde_json::to_string_pretty(&failed.explanation) {
                Ok(json) if args.json => println!("{json}"),
                _ => print!("{}", failed.explanation.text()),
            }
        }
    })?;
    let report = write_picture(args, &outcome, IMAGE_NAME)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.text());
    }
    Ok(())
}

/// Writes the outcome's picture as `image_name` into `--out` and returns its report.
fn write_picture(
    args: &QueryArgs,
    outcome: &QueryOutcome,
    image_name: &str,
) -> Result<QueryReport> {
    let written = write_into_folder(&args.out, &[(image_name, &outcome.png)])?;
    let path = &written[0];
    let report = outcome.report(path);
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

/// The query on the scene file of `--scene` with the built-in sources: the config the options
/// make, grounded as a run config is.
fn from_options(args: &QueryArgs, picture: PictureOptions) -> Result<QueryOutcome> {
    let extensions = Extensions::default();
    let config = args.options()?.config(None, &args.set, &extensions)?;
    let query = &config.queries[0].text;
    ConfigQuery {
        picture,
        backend: args.backend,
        source: if args.source_given() {
            SourceChoice::Configured
        } else {
            SourceChoice::FromInputs
        },
        naming: KeyNaming::Options(args::option_naming),
    }
    .prepare(&config, &extensions)?
    .find(query)
}
