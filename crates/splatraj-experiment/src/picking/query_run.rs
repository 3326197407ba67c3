//! `splatraj query` in one call ([`run_query`]): the config made of the options (or a run
//! config's with the options over its keys), its scene read and source built once, then the
//! query asked (or, with a config and no query, each of the config's queries, one failing not
//! stopping the others) and each picture written into the output folder. The command parses
//! its flags into a [`QueryRequest`] and prints the answers.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use splatraj_render::backend::BackendKind;

use super::query::{
    ConfigQuery, ConfigQueryText, KeyNaming, PictureOptions, QueryOutcome, QueryReport,
    SourceChoice, config_query_texts,
};
use super::query_options::QueryOptions;
use crate::extensions::Extensions;
use crate::write::write_into_folder;

/// Name of the picture of a single query.
pub const IMAGE_NAME: &str = "query.png";

/// Everything `splatraj query` is asked.
#[derive(Debug, Clone)]
pub struct QueryRequest<'a> {
    /// A run config whose `[scene]` and `[targets]` the options override; None: the options
    /// make a config of their own.
    pub config: Option<&'a Path>,
    /// The scene and source options, typed (their `query` is the query asked; with a config
    /// and none, every query of the config).
    pub options: QueryOptions,
    /// `KEY=VALUE` overrides, over the file and the options.
    pub set: &'a [String],
    /// The picture.
    pub picture: PictureOptions,
    /// The backend; None: the config's.
    pub backend: Option<BackendKind>,
    /// Whether the options chose the source; without a config and without it, the inputs
    /// point to it.
    pub source_given: bool,
    /// Without a config, the option that sets a `[targets]` key, for errors.
    pub option_naming: fn(&str) -> String,
    /// The folder the pictures go into (created if missing).
    pub out: &'a Path,
}

/// One query answered: its picture written, and its report.
#[derive(Debug, Clone)]
pub struct Answered {
    /// What `query` prints (text or JSON), naming the picture.
    pub report: QueryReport,
    /// The picture written.
    pub picture: PathBuf,
    /// Share of the picture's pixels where the selection dominates.
    pub highlighted_share: f64,
}

/// One of a config's queries, and its answer or why it failed.
#[derive(Debug)]
pub struct ConfigAnswer {
    /// The text and the config key that holds it.
    pub item: ConfigQueryText,
    /// Its answer, or the error (a [`super::query::SelectionFailed`] carries the explanation).
    pub answer: Result<Answered>,
}

/// What [`run_query`] answered.
#[derive(Debug)]
pub enum QueryAnswers {
    /// The one query asked, pictured as [`IMAGE_NAME`].
    One(Box<Answered>),
    /// Each query of the config, in order, each pictured as `query-N.png` (`query-N-M.png`
    /// for a group shot's objects), N the `[[queries]]` entry from 1.
    Each(Vec<ConfigAnswer>),
}

impl QueryAnswers {
    /// The error of a config's queries when some failed, naming each, e.g. `config C: 1 of 3
    /// queries failed: queries.1.text ("vase")`.
    pub fn failures(&self, config: &Path) -> Option<String> {
        let QueryAnswers::Each(answers) = self else {
            return None;
        };
        let failed: Vec<String> = answers
            .iter()
            .filter(|a| a.answer.is_err())
            .map(|a| format!("{} ({:?})", a.item.key(), a.item.text))
            .collect();
        (!failed.is_empty()).then(|| {
            format!(
                "config {}: {} of {} queries failed: {}",
                config.display(),
                failed.len(),
                answers.len(),
                failed.join(", ")
            )
        })
    }
}

/// `splatraj query` whole (module docs). A single query's failure is the error (a
/// [`super::query::SelectionFailed`] with its explanation); a config's queries are each
/// answered, `each` hearing every answer as it comes.
pub fn run_query(
    request: &QueryRequest<'_>,
    extensions: &Extensions,
    each: &mut dyn FnMut(&ConfigAnswer),
) -> Result<QueryAnswers> {
    let Some(path) = request.config else {
        // The options' own config, grounded as a run config is.
        let config = request.options.config(None, request.set, extensions)?;
        let query = &config.queries[0].text;
        let outcome = ConfigQuery {
            picture: request.picture.clone(),
            backend: request.backend,
            source: if request.source_given {
                SourceChoice::Configured
            } else {
                SourceChoice::FromInputs
            },
            naming: KeyNaming::Options(request.option_naming),
        }
        .prepare(&config, extensions)?
        .find(query)?;
        return Ok(QueryAnswers::One(Box::new(write_picture(
            request.out,
            &outcome,
            IMAGE_NAME,
        )?)));
    };
    // Low to high: the file, the options given, the overrides.
    let config = request
        .options
        .config(Some(path), request.set, extensions)?;
    let texts = config_query_texts(&config);
    let query = request.options.query.as_deref();
    if query.is_none() && texts.is_empty() {
        bail!(
            "config {}: no query to check (every [[queries]] uses a mask file); give --query",
            path.display()
        );
    }
    let prepared = ConfigQuery {
        picture: request.picture.clone(),
        backend: request.backend,
        source: SourceChoice::Configured,
        naming: KeyNaming::Config,
    }
    .prepare(&config, extensions)?;
    if let Some(query) = query {
        let outcome = prepared.find(query)?;
        return Ok(QueryAnswers::One(Box::new(write_picture(
            request.out,
            &outcome,
            IMAGE_NAME,
        )?)));
    }
    let answers = texts
        .into_iter()
        .map(|item| {
            let picture = match item.object {
                None => format!("query-{}.png", item.window + 1),
                Some(j) => format!("query-{}-{}.png", item.window + 1, j + 1),
            };
            let answer = prepared
                .find(&item.text)
                .and_then(|outcome| write_picture(request.out, &outcome, &picture));
            let answer = ConfigAnswer { item, answer };
            each(&answer);
            answer
        })
        .collect();
    Ok(QueryAnswers::Each(answers))
}

/// Writes the outcome's picture as `name` into `out` and reports it.
fn write_picture(out: &Path, outcome: &QueryOutcome, name: &str) -> Result<Answered> {
    let written = write_into_folder(out, &[(name, &outcome.png)])?;
    let picture = written[0].clone();
    Ok(Answered {
        report: outcome.report(&picture),
        picture,
        highlighted_share: outcome.highlighted_share,
    })
}
