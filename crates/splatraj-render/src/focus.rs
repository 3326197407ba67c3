//! The object of a mask pass as the decisions and the binning read it, derived once per mask.
//!
//! A mask pass decides the object's Gaussians first (by their sorted positions, block order)
//! and bins with a membership test by scene index. Listing the object's sorted positions
//! visits all N Gaussians in scattered order (on 6 M Gaussians 10–20 ms per pass, as much as
//! deciding the object itself), so the result is kept per scene for the masks seen lately
//! ([`FocusCache`]); a pass then only turns its mask into bits (one sequential scan of `N / 64`
//! words) to find it.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, PoisonError};

use crate::bitset::GaussianBits;

/// A mask pass's object: its Gaussians by scene index and by sorted position.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjectFocus {
    /// Members by scene index (tile lists hold scene indices). `[N] bits`
    pub scene: GaussianBits,
    /// Members by sorted position of the host geometry (`decide::HostGeometry`: the
    /// decisions walk blocks in that order). `[N] bits`
    pub sorted: GaussianBits,
    /// The members' sorted positions, increasing. `[object]`
    pub sorted_list: Vec<u32>,
}

impl ObjectFocus {
    /// The object whose scene indices are `scene`, placed in the sorted order whose scene
    /// index at each position is `scene_from_sorted`.
    pub fn new(scene_from_sorted: &[u32], scene: GaussianBits) -> Self {
        let sorted = GaussianBits::from_fn(scene_from_sorted.len(), |k| {
            scene.contains(scene_from_sorted[k] as usize)
        });
        let sorted_list = sorted.iter().map(|k| k as u32).collect();
        ObjectFocus {
            scene,
            sorted,
            sorted_list,
        }
    }

    /// The object of one flag per Gaussian (scene order).
    pub fn from_flags(scene_from_sorted: &[u32], in_object: &[bool]) -> Self {
        Self::new(
            scene_from_sorted,
            GaussianBits::from_fn(in_object.len(), |g| in_object[g]),
        )
    }
}

/// What a pose of a mask pass draws around its object.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Surroundings {
    /// The scene: whatever can cover the object is drawn (the object as the camera sees it).
    #[default]
    Scene,
    /// Nothing: the object alone, as if the rest of the scene were not there (the visibility
    /// cost's unoccluded mask).
    Nothing,
}

/// One pose's object in a mask pass, and what the pose draws around it.
#[derive(Debug, Clone, Copy)]
pub struct PoseFocus<'a> {
    /// The object.
    pub object: &'a ObjectFocus,
    /// The scene around it, or nothing.
    pub surroundings: Surroundings,
}

/// Masks whose focus a scene keeps: one per object of a run (a step renders every window's
/// object in one pass), with room to spare.
const CACHED_MASKS: usize = 16;

/// The [`ObjectFocus`] of the masks a scene rendered lately, found by the mask's non-zero
/// pattern (all a focus depends on), so the answer is always the one a fresh build would give.
#[derive(Default)]
pub struct FocusCache {
    /// Most recently built last.
    recent: Mutex<VecDeque<Arc<ObjectFocus>>>,
}

impl FocusCache {
    /// The focus of `mask` (one value per Gaussian, non-zero inside the object) in the sorted
    /// order `scene_from_sorted` ([`ObjectFocus::new`]).
    pub fn focus(&self, scene_from_sorted: &[u32], mask: &[f32]) -> Arc<ObjectFocus> {
        let scene = GaussianBits::from_fn(mask.len(), |g| mask[g] != 0.0);
        let mut recent = self.recent.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(known) = recent.iter().find(|f| f.scene == scene) {
            return Arc::clone(known);
        }
        let built = Arc::new(ObjectFocus::new(scene_from_sorted, scene));
        if recent.len() == CACHED_MASKS {
            recent.pop_front();
        }
        recent.push_back(Arc::clone(&built));
        built
    }
}

impl Clone for FocusCache {
    /// An empty cache: a clone rebuilds what it needs.
    fn clone(&self) -> Self {
        FocusCache::default()
    }
}

impl std::fmt::Debug for FocusCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let held = self
            .recent
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .len();
        write!(f, "FocusCache({held} masks)")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decide::HostGeometry;
    use splatraj_scene::Scene;

    #[test]
    fn cached_focus_equals_a_fresh_one_for_every_mask() {
        let mut scene = Scene::default();
        for i in 0..700 {
            let x = ((i * 37) % 101) as f32 / 10.0;
            scene.means.push([x, (i % 13) as f32, (i % 5) as f32]);
            scene.scales.push([0.1; 3]);
            scene.rotations.push([1.0, 0.0, 0.0, 0.0]);
            scene.opacities.push(0.5);
        }
        let geometry = HostGeometry::new(&scene);
        let masks: Vec<Vec<f32>> = (2..5)
            .map(|m| (0..700).map(|i| f32::from(u8::from(i % m == 0))).collect())
            .collect();
        // Alternating masks, as the windows of a run do; the same pattern with other non-zero
        // values is the same object.
        for round in 0..3 {
            for mask in &masks {
                let scaled: Vec<f32> = mask.iter().map(|v| v * (round + 1) as f32).collect();
                let flags: Vec<bool> = mask.iter().map(|&v| v != 0.0).collect();
                let order = &geometry.scene_from_sorted;
                let fresh = ObjectFocus::from_flags(order, &flags);
                assert_eq!(*geometry.focus.focus(order, &scaled), fresh);
                let listed: Vec<u32> = (0..700u32)
                    .filter(|&k| flags[geometry.scene_from_sorted[k as usize] as usize])
                    .collect();
                assert_eq!(fresh.sorted_list, listed);
            }
        }
    }
}
