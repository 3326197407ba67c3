//! `splatraj scene views`: the page is written, and bad input ends with one line naming the
//! file, a non-zero status and no page (tests/browser/views_page.mjs drives the page itself).

mod common;

use common::{assert_clean_failure, fixture, s, splatraj, stderr};

#[test]
fn writes_the_page_of_a_real_scene() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("views.html");
    let scene = fixture("fruit_drops_minimal.ply");
    let run = splatraj(&[
        "scene",
        "views",
        s(&scene),
        "--out",
        s(&out),
        "--views",
        "2",
        "--size",
        "64",
        "--max-centres",
        "1000",
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    assert!(
        stderr(&run).contains("1000 of 4721 centres carried: counts in the page are estimates"),
        "{}",
        stderr(&run)
    );
    // The tabletop's guess (+z) first in the strip, then two others.
    assert!(
        stderr(&run).contains(
            "which way is up: the page's first strip shows the scene upright for [0, 0, 1] \
             (these views), "
        ),
        "{}",
        stderr(&run)
    );
    let html = std::fs::read_to_string(&out).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert_eq!(html.matches("<figure class=\"up-choice").count(), 3);
    assert!(html.contains("id=\"splatraj-views\""));
    assert!(html.trim_end().ends_with("</html>"));
}

#[test]
fn bad_input_names_the_file_and_leaves_no_page() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("views.html");
    let truncated = dir.path().join("truncated.ply");
    let whole = std::fs::read(fixture("fruit_drops_minimal.ply")).unwrap();
    std::fs::write(&truncated, &whole[..whole.len() / 2]).unwrap();
    let run = splatraj(&["scene", "views", s(&truncated), "--out", s(&out)]);
    assert_clean_failure(&run, &["truncated.ply"]);

    let missing = dir.path().join("missing.ply");
    let run = splatraj(&["scene", "views", s(&missing), "--out", s(&out)]);
    assert_clean_failure(&run, &["missing.ply"]);

    let run = splatraj(&[
        "scene",
        "views",
        s(&fixture("fruit_drops_minimal.ply")),
        "--out",
        s(&out),
        "--size",
        "5",
    ]);
    assert_clean_failure(&run, &["--size 5"]);

    // A folder at the page's name is not replaced.
    std::fs::create_dir(&out).unwrap();
    let run = splatraj(&[
        "scene",
        "views",
        s(&fixture("fruit_drops_minimal.ply")),
        "--out",
        s(&out),
    ]);
    assert_clean_failure(&run, &["views.html", "folder"]);
    std::fs::remove_dir(&out).unwrap();

    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("truncated.ply")]);
}
