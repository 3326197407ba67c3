//! The variants and runs of a study, made once from the config and the command line so that
//! every process of a study (the parent, its children, every shard) makes the same plan.
//!
//! A factor is a config key and its values (`--vary optimiser.iterations=50,100`). One factor
//! at a time (the default) gives the config itself (the baseline) and, for each factor and
//! value, the config with that one value set; the grid gives every combination. A value is
//! applied as `--set` would apply it, except that a TOML table (`camera={width=64,height=48}`)
//! sets each of its keys, merged into the config's table as `extends` merges (a table whose
//! `kind` differs from the config's replaces it whole: `trajectory={kind="waypoint"}`).
//! Variants whose resolved configs are equal are one variant (the first is kept). The plan is
//! made with its typed configs ([`PlannedStudy`]): the base and one per variant, from the
//! config file read once ([`ConfigFile`]). A run is a
//! variant with one seed (`seed`, `seed + 1`, … for `--seeds N`); a single-pose study runs
//! each variant once with `N` random starts instead.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};

use super::text::short_value;
use super::{Design, EvaluationConfig, Quality, StudyConfig, StudyTask};
use crate::config::{Ablation, Config, ConfigFile, Override};
use crate::extensions::Extensions;
use crate::resources::check_study;

/// One factor: a config key and its values as TOML text.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Factor {
    /// Dotted key, as `--set` writes it.
    pub key: String,
    /// Values as TOML text (a bare word is a string).
    pub values: Vec<String>,
}

impl Factor {
    /// Parses `KEY=V1,V2,…` (commas inside `[…]`, `{…}` or quotes do not split).
    pub fn parse(arg: &str) -> Result<Factor> {
        let Some((key, values)) = arg.split_once('=') else {
            bail!("--vary {arg}: expected KEY=V1,V2,… e.g. optimiser.iterations=50,100");
        };
        let key = key.trim();
        if key.is_empty() {
            bail!("--vary {arg}: no key before `=`");
        }
        let values = split_top_level(values);
        if values.iter().any(|v| v.is_empty()) {
            bail!("--vary {arg}: an empty value (values are separated by commas)");
        }
        Ok(Factor {
            key: key.to_string(),
            values,
        })
    }
}

/// Splits at commas outside brackets, braces and quotes; trims each part.
fn split_top_level(text: &str) -> Vec<String> {
    let mut parts = Vec::new();
    let (mut depth, mut quote, mut current) = (0i32, None::<char>, String::new());
    for c in text.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), _) => {}
            (None, '"' | '\'') => quote = Some(c),
            (None, '[' | '{') => depth += 1,
            (None, ']' | '}') => depth -= 1,
            (None, ',') if depth == 0 => {
                parts.push(current.trim().to_string());
                current.clear();
                continue;
            }
            _ => {}
        }
        current.push(c);
    }
    parts.push(current.trim().to_string());
    parts
}

/// The paper's tables as studies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// Table I: single pose, the ablations prior, +TCE, +TRE, +TCE+TRE, for every query, from
    /// 10 random starts each; TCE, TRE, IoU by ablation.
    Table1,
    /// Table II: waypoint, polynomial and RBF trajectories on the config's problem; TCE, TRE,
    /// IoU and LDJ by model, 3 seeds.
    Table2,
}

impl std::str::FromStr for Preset {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "table1" => Ok(Preset::Table1),
            "table2" => Ok(Preset::Table2),
            other => Err(format!(
                "unknown preset `{other}`: expected table1 or table2"
            )),
        }
    }
}

/// One slice of a study's runs: `K/N` takes runs K−1, K−1+N, K−1+2N, … (1-based K).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// This slice, 1-based.
    pub index: usize,
    /// Slices in all.
    pub count: usize,
}

impl std::str::FromStr for Shard {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || format!("--shard {s}: expected K/N with 1 ≤ K ≤ N, e.g. 2/8");
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count): (usize, usize) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if index == 0 || index > count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

impl Shard {
    /// Whether run `run` belongs to this slice.
    pub fn holds(&self, run: usize) -> bool {
        run % self.count == self.index - 1
    }
}

/// One variant: the settings that make it and the `--set` assignments they become.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Variant {
    /// Index in the plan.
    pub index: usize,
    /// Short name (`baseline`, `iterations=50`, …).
    pub label: String,
    /// `(key, value text)` as the factors gave them.
    pub settings: Vec<(String, String)>,
    /// The assignments applied over the base config.
    pub overrides: Vec<String>,
}

/// One run: a variant with one seed (trajectory) or with all its starts (pose).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Run {
    /// Index in the plan.
    pub index: usize,
    /// Its variant.
    pub variant: usize,
    /// Repeat index (its seed is the config's seed plus this); 0 for pose runs.
    pub repeat: usize,
}

/// What the command line asks of a study besides the config file.
#[derive(Debug, Clone, Default)]
pub struct PlanOptions {
    /// `--set` overrides of the base config (every variant and the evaluation).
    pub set: Vec<String>,
    /// `--vary` factors (replace the config's and the preset's).
    pub vary: Vec<Factor>,
    /// `--grid`.
    pub grid: bool,
    /// `--seeds`.
    pub seeds: Option<usize>,
    /// `--preset`.
    pub preset: Option<Preset>,
}

/// A study's variants and runs, and everything needed to rebuild each run's config.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StudyPlan {
    /// The config file.
    pub config: PathBuf,
    /// The experiment's name.
    pub name: String,
    /// Overrides of the base config (`--set`, then the preset's).
    pub base_overrides: Vec<String>,
    /// The preset, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub preset: Option<Preset>,
    /// Trajectory or single pose.
    pub task: StudyTask,
    /// One at a time or grid.
    pub design: Design,
    /// The factors.
    pub factors: Vec<Factor>,
    /// Repeats per variant.
    pub seeds: usize,
    /// The base config's seed.
    pub base_seed: u64,
    /// The error judged.
    pub quality: Quality,
    /// Extra table grouped by this key.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table_by: Option<String>,
    /// The base config's value of `table_by` (short form), naming the baseline's group.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub baseline_value: Option<String>,
    /// The fixed evaluation.
    pub evaluation: EvaluationConfig,
    /// The variants.
    pub variants: Vec<Variant>,
    /// The runs, variant-major.
    pub runs: Vec<Run>,
}

/// A study ready to check and run: its plan (what `study.json` records) and the configs the
/// plan was made of.
#[derive(Debug, Clone)]
pub struct PlannedStudy {
    /// The plan.
    pub plan: StudyPlan,
    /// The base config with the plan's base overrides (`--set`, the preset's).
    pub base: Config,
    /// Each variant's config, in the plan's order.
    pub variants: Vec<Config>,
}

impl PlannedStudy {
    /// The plan for the config `file` (read once) and `options`, with every variant's config
    /// made and checked from it, so a bad value fails here naming its `--vary`/`[study]`
    /// setting.
    pub fn new(file: &ConfigFile, options: &PlanOptions, extensions: &Extensions) -> Result<Self> {
        let mut base_overrides = options.set.clone();
        if let Some(preset) = options.preset {
            base_overrides.extend(preset_overrides(preset));
        }
        let base_edits = Override::parse_all(&base_overrides)?;
        let base = file.config(&base_edits, extensions)?;
        let mut study = base.study.clone();
        if let Some(preset) = options.preset {
            apply_preset(preset, &base, &mut study);
        }
        if options.grid {
            study.design = Design::Grid;
        }
        if let Some(seeds) = options.seeds {
            study.seeds = seeds;
        }
        study.validate().map_err(|e| {
            anyhow::anyhow!(
                "{e}{}",
                if options.seeds == Some(0) {
                    " (--seeds)"
                } else {
                    ""
                }
            )
        })?;
        // Each value parsed (or, for the default sweep, made) once: the text is the plan's
        // record and label, the value what the variant sets.
        let parsed: Vec<FactorValues> = if !options.vary.is_empty() {
            options
                .vary
                .iter()
                .map(FactorValues::parse)
                .collect::<Result<_>>()?
        } else if !study.vary.is_empty() {
            study
                .vary
                .iter()
                .map(|f| FactorValues {
                    factor: Factor {
                        key: f.key.clone(),
                        values: f.values.iter().map(value_text).collect(),
                    },
                    values: f.values.clone(),
                })
                .collect()
        } else {
            default_sweep(&base)
        };
        let factors: Vec<Factor> = parsed.iter().map(|f| f.factor.clone()).collect();
        // The base config as TOML, only read: which keys hold tables (and of what kind) for a
        // table value, and the baseline's value for the table; never made into a config again.
        let base_table = toml::Table::try_from(&base).context("serialising the config")?;
        let baseline_value = study
            .table_by
            .as_ref()
            .and_then(|k| lookup(&base_table, k))
            .map(|v| short_value(&v.to_string()));
        // Sized before any variant is made: a grid multiplies the values' counts.
        let variant_count = match study.design {
            Design::OneAtATime => 1.0 + factors.iter().map(|f| f.values.len() as f64).sum::<f64>(),
            Design::Grid => factors.iter().map(|f| f.values.len() as f64).product(),
        };
        let seeds = match study.task {
            StudyTask::Trajectory => study.seeds,
            StudyTask::Pose => 1,
        };
        check_study(variant_count, study.seeds, variant_count * seeds as f64)?;
        let settings = match study.design {
            Design::OneAtATime => one_at_a_time(&factors),
            Design::Grid => grid(&factors),
        };
        let mut variants: Vec<Variant> = Vec::new();
        let mut configs: Vec<Config> = Vec::new();
        for settings in settings {
            let label = label(&settings);
            let edits: Vec<Override> = settings
                .iter()
                .map(|(k, text)| assignments(&base_table, k, text, value_of(&parsed, k, text)))
                .collect::<Result<Vec<_>>>()
                .with_context(|| format!("study variant `{label}`"))?
                .into_iter()
                .flatten()
                .collect();
            let mut all = base_edits.clone();
            all.extend(edits.iter().cloned());
            let variant_config = file
                .config(&all, extensions)
                .with_context(|| format!("study variant `{label}`"))?;
            if configs.contains(&variant_config) {
                continue;
            }
            configs.push(variant_config);
            variants.push(Variant {
                index: variants.len(),
                label,
                settings,
                overrides: edits.into_iter().map(|o| o.written).collect(),
            });
        }
        let runs = match study.task {
            StudyTask::Trajectory => variants
                .iter()
                .flat_map(|v| (0..study.seeds).map(move |repeat| (v.index, repeat)))
                .enumerate()
                .map(|(index, (variant, repeat))| Run {
                    index,
                    variant,
                    repeat,
                })
                .collect(),
            StudyTask::Pose => variants
                .iter()
                .map(|v| Run {
                    index: v.index,
                    variant: v.index,
                    repeat: 0,
                })
                .collect(),
        };
        let plan = StudyPlan {
            config: file.path.clone(),
            name: base.name.clone(),
            base_overrides,
            preset: options.preset,
            task: study.task,
            design: study.design,
            factors,
            seeds: study.seeds,
            base_seed: base.seed,
            quality: study.quality,
            table_by: study.table_by.clone(),
            baseline_value,
            evaluation: study.evaluation.clone(),
            variants,
            runs,
        };
        Ok(PlannedStudy {
            plan,
            base,
            variants: configs,
        })
    }
}

impl StudyPlan {
    /// The runs of `shard` (all runs without one).
    pub fn runs_of(&self, shard: Option<Shard>) -> Vec<Run> {
        self.runs
            .iter()
            .filter(|r| shard.is_none_or(|s| s.holds(r.index)))
            .copied()
            .collect()
    }
}

/// A TOML value as the text a factor holds (inline tables on one line).
fn value_text(value: &toml::Value) -> String {
    value.to_string()
}

/// The base overrides a preset adds (random starts, as the paper's repetitions).
fn preset_overrides(preset: Preset) -> Vec<String> {
    match preset {
        Preset::Table1 => vec!["start.kind=\"random\"".into()],
        Preset::Table2 => Vec::new(),
    }
}

/// What a preset sets in `[study]` (the command line may still change the design or seeds).
fn apply_preset(preset: Preset, base: &Config, study: &mut StudyConfig) {
    match preset {
        Preset::Table1 => {
            let ablations = [
                Ablation::Prior,
                Ablation::PriorTce,
                Ablation::PriorTre,
                Ablation::PriorTceTre,
            ];
            study.task = StudyTask::Pose;
            study.design = Design::Grid;
            study.seeds = 10;
            study.table_by = Some("pose.ablation".into());
            study.vary = vec![
                super::FactorConfig {
                    key: "pose.ablation".into(),
                    values: ablations
                        .iter()
                        .map(|a| toml::Value::String(a.name().into()))
                        .collect(),
                },
                super::FactorConfig {
                    key: "pose.query".into(),
                    values: (0..base.queries.len())
                        .map(|q| toml::Value::Integer(q as i64))
                        .collect(),
                },
            ];
        }
        Preset::Table2 => {
            study.task = StudyTask::Trajectory;
            study.design = Design::OneAtATime;
            study.seeds = 3;
            study.table_by = Some("trajectory".into());
            let kind = |k: &str| {
                let mut t = toml::Table::new();
                t.insert("kind".into(), toml::Value::String(k.into()));
                toml::Value::Table(t)
            };
            // The config's own model is the baseline; the other two replace it whole.
            study.vary = vec![super::FactorConfig {
                key: "trajectory".into(),
                values: ["waypoint", "polynomial", "rbf"]
                    .into_iter()
                    .filter(|k| *k != base.trajectory.name())
                    .map(kind)
                    .collect(),
            }];
        }
    }
}

/// The default sweep: every accuracy-for-time knob around the config (half and twice the
/// optimisation resolution, samples per window and iterations; two stop transmittances and
/// opacity floors; the other precision and rasterizer), each value made as a TOML value with
/// the text the plan records.
fn default_sweep(base: &Config) -> Vec<FactorValues> {
    let (w, h) = (base.camera.width, base.camera.height);
    let size = |w: usize, h: usize| {
        let table = toml::Table::from_iter([
            ("width".to_string(), integer(w)),
            ("height".to_string(), integer(h)),
        ]);
        (
            format!("{{width={w},height={h}}}"),
            toml::Value::Table(table),
        )
    };
    let mut resolutions = Vec::new();
    if w >= 16 && h >= 16 {
        resolutions.push(size(w / 2, h / 2));
    }
    resolutions.push(size(w * 2, h * 2));
    let count = |n: usize| (n.to_string(), integer(n));
    let s = base.optimiser.samples_per_window;
    let i = base.optimiser.iterations;
    let mut samples = vec![(s / 2).max(1), s * 2];
    samples.dedup();
    let number = |text: &str, x: f64| (text.to_string(), toml::Value::Float(x));
    let word = |w: &str| (format!("\"{w}\""), toml::Value::String(w.to_string()));
    let other_precision = match base.precision {
        splatraj_render::backend::Precision::F32 => "f64",
        splatraj_render::backend::Precision::F64 => "f32",
    };
    let other_rasterizer = match base.rasterizer {
        splatraj_render::render::Rasterizer::Fused => "tensor",
        splatraj_render::render::Rasterizer::Tensor => "fused",
    };
    [
        ("camera", resolutions),
        (
            "optimiser.samples_per_window",
            samples.into_iter().map(count).collect(),
        ),
        (
            "optimiser.iterations",
            vec![count((i / 2).max(1)), count(i * 2)],
        ),
        (
            "approximations.stop_transmittance",
            vec![number("0.001", 0.001), number("0.01", 0.01)],
        ),
        (
            "approximations.min_opacity",
            vec![number("0.02", 0.02), number("0.1", 0.1)],
        ),
        ("precision", vec![word(other_precision)]),
        ("rasterizer", vec![word(other_rasterizer)]),
    ]
    .into_iter()
    .map(|(key, values)| FactorValues::made(key, values))
    .collect()
}

/// `n` as a TOML integer.
fn integer(n: usize) -> toml::Value {
    toml::Value::Integer(i64::try_from(n).unwrap_or(i64::MAX))
}

/// A factor with each value twice: as the text the plan records (and labels show), and as the
/// TOML value a variant sets, parsed or made once.
struct FactorValues {
    /// The factor as the plan records it.
    factor: Factor,
    /// Its values, in the order of `factor.values`.
    values: Vec<toml::Value>,
}

impl FactorValues {
    /// `factor` with each text value parsed (as `--set` reads a value).
    fn parse(factor: &Factor) -> Result<FactorValues> {
        let values = factor
            .values
            .iter()
            .map(|text| {
                let written = format!("{}={text}", factor.key);
                Override::from_text(&factor.key, text, "--set", &written)
                    .map(|edit| edit.value)
                    .with_context(|| {
                        format!(
                            "study variant `{}`",
                            label(&[(factor.key.clone(), text.clone())])
                        )
                    })
            })
            .collect::<Result<_>>()?;
        Ok(FactorValues {
            factor: factor.clone(),
            values,
        })
    }

    /// The factor `key` with `values` made in code, each with its text.
    fn made(key: &str, values: Vec<(String, toml::Value)>) -> FactorValues {
        let (texts, values) = values.into_iter().unzip();
        FactorValues {
            factor: Factor {
                key: key.to_string(),
                values: texts,
            },
            values,
        }
    }
}

/// The value of factor `key` written `text`.
fn value_of<'a>(factors: &'a [FactorValues], key: &str, text: &str) -> &'a toml::Value {
    factors
        .iter()
        .filter(|f| f.factor.key == key)
        .find_map(|f| {
            let at = f.factor.values.iter().position(|t| t == text)?;
            f.values.get(at)
        })
        .expect("every setting comes from a factor")
}

/// The baseline, then each factor's values alone.
fn one_at_a_time(factors: &[Factor]) -> Vec<Vec<(String, String)>> {
    let mut out = vec![Vec::new()];
    for f in factors {
        for v in &f.values {
            out.push(vec![(f.key.clone(), v.clone())]);
        }
    }
    out
}

/// Every combination, the first factor varying slowest.
fn grid(factors: &[Factor]) -> Vec<Vec<(String, String)>> {
    factors.iter().fold(vec![Vec::new()], |acc, f| {
        acc.iter()
            .flat_map(|prefix| {
                f.values.iter().map(move |v| {
                    let mut s = prefix.clone();
                    s.push((f.key.clone(), v.clone()));
                    s
                })
            })
            .collect()
    })
}

/// `short=value …` (the key's last segment, the value without spaces), or `baseline`.
fn label(settings: &[(String, String)]) -> String {
    if settings.is_empty() {
        return "baseline".into();
    }
    settings
        .iter()
        .map(|(k, v)| {
            let short = k.rsplit('.').next().unwrap_or(k);
            let v: String = v.chars().filter(|c| !c.is_whitespace()).collect();
            format!("{short}={}", v.trim_matches('"'))
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// The edits of `key` = `value` (written `text`) over `base`, each written as `--set` would
/// write it: a table value sets each of its keys when the base holds a table there with the
/// same `kind` (or none), else the value is set whole.
fn assignments(
    base: &toml::Table,
    key: &str,
    text: &str,
    value: &toml::Value,
) -> Result<Vec<Override>> {
    match (value, lookup(base, key)) {
        (toml::Value::Table(over), Some(toml::Value::Table(existing)))
            if over
                .get("kind")
                .is_none_or(|k| Some(k) == existing.get("kind")) =>
        {
            flatten(key, over)
        }
        _ => Ok(vec![Override::new(
            key,
            value.clone(),
            "--set",
            &format!("{key}={text}"),
        )?]),
    }
}

/// An edit of `prefix.k` for every leaf `k` of `table`, written `prefix.k=v`.
fn flatten(prefix: &str, table: &toml::Table) -> Result<Vec<Override>> {
    let mut edits = Vec::new();
    for (k, v) in table {
        let key = format!("{prefix}.{k}");
        match v {
            toml::Value::Table(t) => edits.extend(flatten(&key, t)?),
            v => edits.push(Override::new(
                &key,
                v.clone(),
                "--set",
                &format!("{key}={v}"),
            )?),
        }
    }
    Ok(edits)
}

/// The value at a dotted key (numeric segments index arrays).
fn lookup<'a>(table: &'a toml::Table, key: &str) -> Option<&'a toml::Value> {
    let mut parts = key.split('.');
    let mut node = table.get(parts.next()?.trim())?;
    for part in parts {
        node = match node {
            toml::Value::Table(t) => t.get(part.trim())?,
            toml::Value::Array(a) => a.get(part.trim().parse::<usize>().ok()?)?,
            _ => return None,
        };
    }
    Some(node)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_split_at_top_level_commas_only() {
        let f = Factor::parse("camera={width=64,height=48},{width=8,height=6}").unwrap();
        assert_eq!(f.key, "camera");
        assert_eq!(f.values, ["{width=64,height=48}", "{width=8,height=6}"]);
        let f = Factor::parse("queries.0.text=\"a,b\",lamp").unwrap();
        assert_eq!(f.values, ["\"a,b\"", "lamp"]);
        assert!(Factor::parse("iterations").is_err());
        assert!(Factor::parse("x=1,,2").is_err());
    }

    #[test]
    fn grid_and_one_at_a_time_count_their_variants() {
        let f = |k: &str, n: usize| Factor {
            key: k.into(),
            values: (0..n).map(|i| i.to_string()).collect(),
        };
        let factors = [f("a", 2), f("b", 3)];
        assert_eq!(one_at_a_time(&factors).len(), 1 + 2 + 3);
        let g = grid(&factors);
        assert_eq!(g.len(), 6);
        assert_eq!(
            g[1],
            vec![("a".into(), "0".into()), ("b".into(), "1".into())]
        );
    }

    /// The edits of `key = raw` over `base`, as written.
    fn written(base: &toml::Table, key: &str, raw: &str) -> Vec<String> {
        let value = Override::from_text(key, raw, "--set", raw).unwrap().value;
        let edits = assignments(base, key, raw, &value).unwrap();
        edits.into_iter().map(|o| o.written).collect()
    }

    #[test]
    fn a_table_value_merges_unless_its_kind_differs() {
        let base: toml::Table =
            toml::from_str("[camera]\nwidth = 1\nfov_x = 60.0\n[trajectory]\nkind = \"rbf\"\ncentres_per_window = 8\n")
                .unwrap();
        assert_eq!(
            written(&base, "camera", "{width=64,height=48}"),
            ["camera.height=48", "camera.width=64"]
        );
        assert_eq!(
            written(&base, "trajectory", "{kind=\"waypoint\"}"),
            ["trajectory={kind=\"waypoint\"}"]
        );
        assert_eq!(
            written(&base, "trajectory", "{kind=\"rbf\"}"),
            ["trajectory.kind=\"rbf\""]
        );
    }

    #[test]
    fn the_default_sweeps_values_are_what_their_texts_read_as() {
        let text = "name = \"x\"\n[scene]\ndemo = { gaussians = 100 }\n[[queries]]\ntext = \"a\"\n";
        let base =
            Config::from_toml(text, std::path::Path::new("."), &Extensions::default()).unwrap();
        let sweep = default_sweep(&base);
        assert_eq!(sweep.len(), 7);
        for f in &sweep {
            assert_eq!(f.factor.values.len(), f.values.len());
            for (text, value) in f.factor.values.iter().zip(&f.values) {
                let read = Override::from_text(&f.factor.key, text, "--set", text).unwrap();
                assert_eq!(read.value, *value, "{} = {text}", f.factor.key);
            }
        }
    }

    #[test]
    fn shards_partition_the_runs() {
        let shards: Vec<Shard> = (1..=3).map(|k| format!("{k}/3").parse().unwrap()).collect();
        for run in 0..10 {
            assert_eq!(shards.iter().filter(|s| s.holds(run)).count(), 1);
        }
        assert!("0/3".parse::<Shard>().is_err());
        assert!("4/3".parse::<Shard>().is_err());
    }
}
