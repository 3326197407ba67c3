//! What `splatraj scene lift-masks` prints of a [`MaskLift`]: the cameras used, the labels
//! found with their Gaussians, and the share no masked camera showed.

use std::collections::BTreeMap;

use crate::mask_files::{MaskCoding, MaskLift};

impl MaskLift {
    /// How many Gaussians the lift gave a label (id ≠ 0).
    pub fn labelled(&self) -> usize {
        self.labels.ids.iter().filter(|&&id| id != 0).count()
    }

    /// What `scene lift-masks` prints: cameras used, the labels with their Gaussians, the unseen
    /// share.
    pub fn summary_text(&self) -> String {
        let lift = self;
        let cameras = lift.masked.len() + lift.unmasked.len();
        let mut out = format!("cameras:    {} of {cameras} with a mask", lift.masked.len());
        if !lift.unmasked.is_empty() {
            let shown: Vec<&str> = lift.unmasked.iter().take(5).map(String::as_str).collect();
            out += &format!(
                " ({} skipped: {}{})",
                lift.unmasked.len(),
                shown.join(", "),
                if lift.unmasked.len() > shown.len() {
                    ", …"
                } else {
                    ""
                }
            );
        }
        out += &format!(
            "\nmasks:      {}\n",
            match lift.coding {
                MaskCoding::Grey => "grey (values are label ids)".to_string(),
                MaskCoding::Colour => format!("colour-coded ({} colours)", lift.legend.len()),
            }
        );
        let mut counts: BTreeMap<i32, usize> = BTreeMap::new();
        for &id in &lift.labels.ids {
            *counts.entry(id).or_insert(0) += 1;
        }
        let found: Vec<i32> = lift
            .labels
            .labels
            .iter()
            .copied()
            .filter(|&l| l != 0)
            .collect();
        out += &format!("labels:     {} in the masks\n", found.len());
        let names: BTreeMap<i32, String> = lift.legend.iter().map(|e| (e.id, e.name())).collect();
        for id in &found {
            out += &format!(
                "  {id:>6}  {:>9} Gaussians  {}\n",
                counts.get(id).copied().unwrap_or(0),
                names.get(id).map_or("-", String::as_str)
            );
        }
        let n = lift.labels.ids.len().max(1) as f64;
        out += &format!(
            "unlabelled: {} Gaussians ({:.1} %)\nunseen:     {:.1} % of the Gaussians (no masked \
             camera shows them)\n",
            counts.get(&0).copied().unwrap_or(0),
            100.0 * counts.get(&0).copied().unwrap_or(0) as f64 / n,
            100.0 * lift.unseen_share()
        );
        out
    }
}
