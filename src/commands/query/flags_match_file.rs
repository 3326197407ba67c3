//! `splatraj query`'s options and the config file that writes the same keys make equal typed
//! configs, with and without `--config`: the options are no second copy of the schema that
//! could drift from it.

use std::path::Path;

use clap::Parser;
use splatraj::experiment::{Config, Extensions};

use super::QueryArgs;

/// `splatraj query` alone, for parsing its arguments.
#[derive(Parser)]
struct Query {
    #[command(flatten)]
    args: QueryArgs,
}

/// The typed config `splatraj query ARGS` makes (`args` split at spaces; without `--config`:
/// the options' own; with it: the file's with the options over it).
fn from_flags(args: &str) -> Config {
    let words = std::iter::once("query").chain(args.split_whitespace());
    let parsed = Query::try_parse_from(words)
        .unwrap_or_else(|e| panic!("{e}"))
        .args;
    parsed
        .options()
        .unwrap()
        .config(
            parsed.config.as_deref(),
            &parsed.set,
            &Extensions::default(),
        )
        .unwrap()
}

/// The typed config of the options' own config written as a file (`name = "query"`, the
/// query as its one `[[queries]]`), `keys` its `[scene]` and `[targets]` tables.
fn from_file(query: &str, keys: &str) -> Config {
    let text = format!("name = \"query\"\n[[queries]]\ntext = \"{query}\"\n{keys}");
    Config::from_toml(&text, Path::new(""), &Extensions::default()).unwrap()
}

#[test]
fn each_option_sets_the_key_a_config_file_writes() {
    let cases: [(&str, &str, &str); 6] = [
        (
            "--scene s.ply --labels l.json --drop-invalid --query mug --source features \
             --features f.npy --phrases p.npy --phrase-names p.txt --text-encoder \
             clip.safetensors --text-activation quick-gelu --negative thing --negative stuff \
             --temperature 5 --top-fraction 0.1 --floor 0.4 --no-cluster",
            "mug",
            r#"[scene]
path = "s.ply"
labels = "l.json"
drop_invalid = true
[targets]
source = "features"
features = "f.npy"
phrases = "p.npy"
phrase_names = "p.txt"
text_encoder = "clip.safetensors"
text_activation = "quick-gelu"
negatives = ["thing", "stuff"]
temperature = 5.0
[targets.selection]
top_fraction = 0.1
floor = 0.4
cluster = false
"#,
        ),
        (
            "--scene s.ply --query mug --synonym mug=cup,beaker",
            "mug",
            "[scene]\npath = \"s.ply\"\n[targets]\nsynonyms = { mug = [\"cup\", \"beaker\"] }\n",
        ),
        (
            "--scene s.ply --query shelf --box=-1,-2,-3,1,2,3",
            "shelf",
            "[scene]\npath = \"s.ply\"\n[targets]\nregions = { shelf = { box = [-1.0, -2.0, \
             -3.0, 1.0, 2.0, 3.0] } }\n",
        ),
        (
            "--scene s.ply --selection head.compressed.ply",
            "head",
            "[scene]\npath = \"s.ply\"\n[targets]\nregions = { head = { selection = \
             \"head.compressed.ply\" } }\n",
        ),
        (
            "--scene s.ply --query 7 --source custom.gaussian_grouping --source-key \
             classifier=c.pth --source-key min_probability=0.5 --synonym teapot=pot",
            "7",
            r#"[scene]
path = "s.ply"
[targets]
source = "custom.gaussian_grouping"
[targets.custom.gaussian_grouping]
classifier = "c.pth"
min_probability = 0.5
synonyms = { teapot = ["pot"] }
"#,
        ),
        (
            "--scene s.ply --query cup --source langsplat --latents z.npy --checkpoint ae.pth \
             --phrases p.json --source-key views.count=8",
            "cup",
            r#"[scene]
path = "s.ply"
[targets]
source = "langsplat"
latents = "z.npy"
checkpoint = "ae.pth"
phrases = "p.json"
lifted = { views = { count = 8 } }
"#,
        ),
    ];
    for (args, query, keys) in cases {
        assert_eq!(from_flags(args), from_file(query, keys), "{args}");
    }
}

#[test]
fn over_a_run_config_the_options_set_its_keys_with_absolute_paths_and_set_wins() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run.toml");
    let base = "name = \"run\"\n[scene]\npath = \"room.ply\"\n[targets]\nsource = \
                \"features\"\nphrases = \"table.json\"\ntemperature = 3.0\n\
                [targets.selection]\ntop_fraction = 0.2\n[[queries]]\ntext = \"lamp\"\n";
    std::fs::write(&run, base).unwrap();
    let made = from_flags(&format!(
        "--config {} --phrases mine.json --floor 0.3 --temperature 4 \
         --set targets.temperature=6.0",
        run.display()
    ));
    // The options' paths are made absolute: the run config reads its own from its folder.
    let phrases = std::path::absolute("mine.json").unwrap();
    let written = dir.path().join("written.toml");
    let text = format!(
        "name = \"run\"\n[scene]\npath = \"room.ply\"\n[targets]\nsource = \"features\"\n\
         phrases = {:?}\ntemperature = 6.0\n[targets.selection]\ntop_fraction = 0.2\n\
         floor = 0.3\n[[queries]]\ntext = \"lamp\"\n",
        phrases.display().to_string()
    );
    std::fs::write(&written, text).unwrap();
    let mut expected = Config::load(&written, &[]).unwrap();
    expected.path = run.clone();
    assert_eq!(made, expected);
}
