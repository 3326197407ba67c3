//! Label sidecars written by `write_label_sidecar` read back to the same ids and names, in both
//! forms, and a path that is not a regular file is not replaced.

use std::collections::BTreeMap;

use splatraj_scene::Labels;
use splatraj_scene::formats::{read_label_sidecar, write_label_sidecar};

fn labels(names: &[(i32, &str)]) -> Labels {
    Labels {
        source: "test".into(),
        ids: vec![0, 3, 3, 7, 0, 12, 7, -1],
        names: names.iter().map(|&(id, n)| (id, n.to_string())).collect(),
    }
}

#[test]
fn sidecars_round_trip_with_and_without_names() {
    let dir = tempfile::tempdir().unwrap();
    for original in [
        labels(&[]),
        labels(&[(3, "#ff0000"), (7, "red mug"), (12, "chair")]),
    ] {
        let path = dir.path().join("labels.json");
        write_label_sidecar(&path, &original).unwrap();
        let back = read_label_sidecar(&path, original.ids.len()).unwrap();
        assert_eq!(back.ids, original.ids);
        assert_eq!(back.names, original.names);
        assert_eq!(back.source, path.display().to_string());
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(
            text.trim_start().starts_with('['),
            original.names == BTreeMap::new()
        );
    }
}

#[test]
fn a_folder_is_not_replaced_by_a_sidecar() {
    let dir = tempfile::tempdir().unwrap();
    let e = write_label_sidecar(dir.path(), &labels(&[]))
        .unwrap_err()
        .to_string();
    assert!(e.contains(&dir.path().display().to_string()), "{e}");
    assert!(e.contains("not a regular file"), "{e}");
    assert!(dir.path().is_dir());
}
