//! `splatraj query`: what a semantic query selects in a scene, as text (or JSON) and as a
//! picture (`query.png`, the selection tinted). The scene and source come from a run config
//! (`--config RUN.toml`, whose keys the options given override) or from the options, which
//! make a config of their own (`args.rs` reads them into the library's typed
//! `QueryOptions`, whose one `config` makes either). The work is one library call,
//! [`run_query`] (`splatraj::experiment::picking::query_run`); this file parses and prints.

mod args;
#[cfg(test)]
mod flags_match_file;

use anyhow::{Result, bail};
use splatraj::experiment::Extensions;
use splatraj::experiment::picking::query::SelectionFailed;
use splatraj::experiment::picking::query_run::{
    Answered, ConfigAnswer, QueryAnswers, QueryRequest, run_query,
};

pub use args::QueryArgs;

/// Runs `splatraj query`.
pub fn run(args: QueryArgs) -> Result<()> {
    // Cheap checks first, then the scene and the source, then the render; the files last.
    if args.query.as_ref().is_some_and(|q| q.trim().is_empty()) {
        bail!("--query is empty: give a label name, a phrase or a region name");
    }
    let request = QueryRequest {
        config: args.config.as_deref(),
        picture: args.picture()?,
        options: args.options()?,
        set: &args.set,
        backend: args.backend,
        source_given: args.source_given(),
        option_naming: args::option_naming,
        out: &args.out,
    };
    // A config's queries: each shown as it is answered. JSON: one array of {key, report} or
    // {key, query, error, explanation}, printed at the end.
    let mut entries = Vec::new();
    let mut each = |answer: &ConfigAnswer| {
        let key = answer.item.key();
        if !args.json {
            println!("== {key}: {}", answer.item.text);
        }
        match &answer.answer {
            Ok(answered) => {
                tell_written(&args, answered);
                if !args.json {
                    print!("{}", answered.report.text());
                }
                entries.push(serde_json::json!({ "key": key, "report": answered.report }));
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
                    "query": answer.item.text,
                    "error": format!("{error:#}"),
                    "explanation": explanation,
                }));
            }
        }
    };
    let answers = run_query(&request, &Extensions::default(), &mut each).inspect_err(|e| {
        // One query whose selection failed: why nothing was selected.
        if let Some(failed) = e.downcast_ref::<SelectionFailed>() {
            match serde_json::to_string_pretty(&failed.explanation) {
                Ok(json) if args.json => println!("{json}"),
                _ => print!("{}", failed.explanation.text()),
            }
        }
    })?;
    match &answers {
        QueryAnswers::One(answered) => {
            tell_written(&args, answered);
            if args.json {
                println!("{}", serde_json::to_string_pretty(&answered.report)?);
            } else {
                print!("{}", answered.report.text());
            }
        }
        QueryAnswers::Each(_) if args.json => {
            println!("{}", serde_json::to_string_pretty(&entries)?)
        }
        QueryAnswers::Each(_) => {}
    }
    if let Some(path) = &args.config
        && let Some(failures) = answers.failures(path)
    {
        bail!("{failures}");
    }
    Ok(())
}

/// The picture's warnings and where it was written.
fn tell_written(args: &QueryArgs, answered: &Answered) {
    for w in &answered.report.warnings {
        eprintln!("warning: {w}");
    }
    eprintln!(
        "wrote {} ({}×{}, {:.1}% of the pixels highlighted)",
        answered.picture.display(),
        args.width,
        args.height,
        100.0 * answered.highlighted_share
    );
}
