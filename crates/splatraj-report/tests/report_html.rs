//! `report.html` from a made-up run: well-formed (parsed as XML), self-contained (no network
//! address in any `src` or `href`), every section there, text escaped, the video inlined whole
//! or linked.

use base64::Engine;
use base64::engine::general_purpose::STANDARD as BASE64;
use splatraj_report::report::{
    CostHistory, FrameMetrics, Keyframe, PathSample, RunReport, SceneView, Shot, Table,
    VideoSource, Window,
};

fn made_up_run(video: VideoSource) -> RunReport {
    let windows = vec![
        Window {
            query: "red mug".into(),
            start: 0.0,
            end: 0.5,
            target_ratio: 0.15,
        },
        Window {
            query: "a <b> & \"c\"".into(),
            start: 0.5,
            end: 1.0,
            target_ratio: 0.2,
        },
    ];
    let along = (0..11)
        .map(|i| {
            let t = i as f64 / 10.0;
            // Frames 3 and 4 do not show their object: no TCE (the line breaks there).
            let shown = !(3..=4).contains(&i);
            FrameMetrics {
                t,
                window: usize::from(t >= 0.5),
                tce: shown.then_some(0.1 * (1.0 - t)),
                tre: 0.05 * t,
                coverage: if shown { 0.15 + 0.02 * t } else { 0.0 },
            }
        })
        .collect();
    let path: Vec<PathSample> = (0..30)
        .map(|i| {
            let a = i as f64 / 29.0 * 3.0;
            PathSample {
                centre: [2.0 * a.cos(), 2.0 * a.sin(), 1.0],
                forward: [-a.cos(), -a.sin(), 0.0],
                window: usize::from(i >= 15),
            }
        })
        .collect();
    let points = (0..500)
        .map(|i| {
            let x = (i % 25) as f32 / 12.0 - 1.0;
            let y = (i / 25) as f32 / 10.0 - 1.0;
            ([x, y, 0.0], [(i % 255) as u8, 100, 150])
        })
        .collect();
    RunReport {
        shots: Vec::new(),
        title: "demo".into(),
        folder: "runs/demo/2026-01-01T00-00-00Z".into(),
        summary: vec![("scene".into(), "demo (seed 7)".into())],
        verdict: Some(vec![
            "window 1 \"a <b> & \"c\"\": 78 % of the object is hidden behind other geometry".into(),
        ]),
        metrics: Table {
            header: vec!["window".into(), "query".into(), "tce".into()],
            rows: vec![
                vec!["0".into(), "red mug".into(), "0.0312".into()],
                vec!["1".into(), "a <b> & \"c\"".into(), "0.0456".into()],
            ],
        },
        keyframes: vec![
            vec![Keyframe {
                t: 0.0,
                name: "frame_0000.png".into(),
                png: vec![0x89, b'P', b'N', b'G', 1, 2, 3],
            }],
            vec![
                Keyframe {
                    t: 0.6,
                    name: "frame_0006.png".into(),
                    png: vec![0x89, b'P', b'N', b'G', 4],
                },
                Keyframe {
                    t: 0.9,
                    name: "frame_0009.png".into(),
                    png: vec![0x89, b'P', b'N', b'G', 5],
                },
            ],
        ],
        along,
        history: Some(CostHistory {
            steps: (0..20).map(f64::from).collect(),
            terms: vec![
                (
                    "tce".into(),
                    (0..20).map(|s| 0.5 / (1.0 + s as f64)).collect(),
                ),
                (
                    "prior".into(),
                    (0..20).map(|s| 2.0 - 0.05 * s as f64).collect(),
                ),
                (
                    "total".into(),
                    (0..20).map(|s| 2.5 - 0.06 * s as f64).collect(),
                ),
            ],
        }),
        view: Some(SceneView {
            up: [0.0, 0.0, 1.0],
            points,
            path,
            objects: vec![
                ("red mug".into(), [1.0, 0.0, 0.5]),
                ("a <b> & \"c\"".into(), [-1.0, 0.5, 0.5]),
            ],
        }),
        video: Some(video),
        config: "name = \"demo\"\n[scene]\ndemo = { gaussians = 3000 }\n".into(),
        windows,
    }
}

/// The page as XML (its DOCTYPE allowed).
fn parse_page(page: &str) -> roxmltree::Document<'_> {
    roxmltree::Document::parse_with_options(
        page,
        roxmltree::ParsingOptions {
            allow_dtd: true,
            ..Default::default()
        },
    )
    .unwrap()
}

fn attributes<'a>(doc: &'a roxmltree::Document<'a>, name: &'a str) -> Vec<&'a str> {
    doc.descendants()
        .flat_map(|n| n.attributes())
        .filter(|a| a.name() == name)
        .map(|a| a.value())
        .collect()
}

#[test]
fn the_page_is_well_formed_self_contained_and_complete() {
    let video = vec![0u8, 0, 0, 24, b'f', b't', b'y', b'p', 9, 9, 9];
    let html = made_up_run(VideoSource::Inline(video.clone()))
        .to_html()
        .unwrap();
    assert!(html.starts_with("<!DOCTYPE html>"));
    let doc = roxmltree::Document::parse_with_options(
        &html,
        roxmltree::ParsingOptions {
            allow_dtd: true,
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("report.html is not well-formed: {e}"));
    assert_eq!(doc.root_element().tag_name().name(), "html");

    // Nothing to fetch: every src is a data: URI, every href an anchor in the page.
    for src in attributes(&doc, "src") {
        assert!(src.starts_with("data:"), "{}", &src[..src.len().min(40)]);
    }
    for href in attributes(&doc, "href") {
        assert!(href.starts_with('#'), "{href}");
    }
    let count = |tag: &str| {
        doc.descendants()
            .filter(|n| n.tag_name().name() == tag)
            .count()
    };
    // Along t, cost history, top and side views.
    assert_eq!(count("svg"), 4);
    assert_eq!(count("img"), 3);
    assert_eq!(count("video"), 1);
    let ids: Vec<&str> = attributes(&doc, "id");
    for id in [
        "summary",
        "video",
        "keyframes",
        "along",
        "history",
        "views",
        "config",
    ] {
        assert!(ids.contains(&id), "section {id} missing");
    }

    let src = attributes(&doc, "src")
        .into_iter()
        .find(|s| s.starts_with("data:video/mp4;base64,"))
        .unwrap();
    let back = BASE64
        .decode(&src["data:video/mp4;base64,".len()..])
        .unwrap();
    assert_eq!(back, video);

    // Text arrives as text: the odd query name survives escaping in the table, the keyframe
    // heading and both views' labels.
    let texts: Vec<&str> = doc.descendants().filter_map(|n| n.text()).collect();
    assert!(texts.contains(&"a <b> & \"c\""));
    assert!(
        texts
            .iter()
            .filter(|t| t.contains("1: a <b> & \"c\""))
            .count()
            >= 2
    );
    assert!(texts.iter().any(|t| t.contains("gaussians = 3000")));
    assert!(texts.contains(&"0.0456"));

    // A failed verdict opens the page: its banner comes before the summary and holds the
    // console's words.
    let verdict = doc
        .descendants()
        .find(|n| n.attribute("id") == Some("verdict"))
        .expect("a verdict banner");
    let summary = doc
        .descendants()
        .find(|n| n.attribute("id") == Some("summary"))
        .unwrap();
    assert!(verdict.range().start < summary.range().start);
    let words: String = verdict.descendants().filter_map(|n| n.text()).collect();
    assert!(
        words.contains("window 1 \"a <b> & \"c\"\": 78 % of the object is hidden"),
        "{words}"
    );
    let passing = RunReport {
        verdict: Some(Vec::new()),
        ..made_up_run(VideoSource::Link("video.mp4".into()))
    }
    .to_html()
    .unwrap();
    assert!(!passing.contains("id=\"verdict\"") && passing.contains("every window shows"));
}

#[test]
fn a_large_video_is_linked_beside_the_page() {
    let html = made_up_run(VideoSource::Link("video.mp4".into()))
        .to_html()
        .unwrap();
    let doc = parse_page(&html);
    assert!(attributes(&doc, "src").contains(&"video.mp4"));
    assert!(attributes(&doc, "href").contains(&"video.mp4"));
}

#[test]
fn the_shot_list_names_each_shot_its_cut_and_shows_its_first_frame() {
    let run = RunReport {
        shots: vec![
            Shot {
                windows: vec![0],
                queries: vec!["red mug".into()],
                start: 0.0,
                end: 0.5,
                cut_reason: None,
            },
            Shot {
                windows: vec![1],
                queries: vec!["a <b> & \"c\"".into()],
                start: 0.5,
                end: 1.0,
                cut_reason: Some("a pan turning 170° needs 5.7 s".into()),
            },
        ],
        ..made_up_run(VideoSource::Link("video.mp4".into()))
    };
    let page = run.to_html().unwrap();
    let doc = parse_page(&page);
    let section = doc
        .descendants()
        .find(|n| n.attribute("id") == Some("shots"))
        .expect("a shots section");
    let words: String = section.descendants().filter_map(|n| n.text()).collect();
    assert!(
        words.contains("a cut: a pan turning 170° needs 5.7 s"),
        "{words}"
    );
    assert!(words.contains("1: a <b> & \"c\""), "{words}");
    let thumbnails = section
        .descendants()
        .filter(|n| n.has_tag_name("img"))
        .count();
    assert_eq!(thumbnails, 2);
    // A run folder from before the shot list says so.
    assert!(
        made_up_run(VideoSource::Link("video.mp4".into()))
            .to_html()
            .unwrap()
            .contains("No shot list in this run folder")
    );
}
