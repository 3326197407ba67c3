//! What the optimisation passes render: the scene itself, or the coarse copy that
//! `optimise_gaussians` asks for on a large scene, with each window's mask carried over.
//! Metrics, verdicts and frames never come here: they render [`Experiment::scene`].

use std::borrow::Cow;

use anyhow::{Context, Result};
use burn::tensor::Device;
use splatraj_render::render::DeviceScene;
use splatraj_scene::Scene;
use splatraj_scene::coarse::{MAX_CLASSES, coarsen};
use splatraj_traj::optimise::WindowTarget;

use crate::prepare::experiment::{CoarseCopy, Derived, Experiment};

impl Experiment {
    /// Builds the coarse copy when `optimise_gaussians` asks for one (after the queries are
    /// grounded: a merged Gaussian never mixes Gaussians of different objects) and records it
    /// in [`Experiment::derived`].
    pub(crate) fn build_coarse_copy(&mut self) -> Result<()> {
        let n = self.scene.len();
        let Some(budget) = self.config.optimise_gaussians.budget(n) else {
            return Ok(());
        };
        // Class of a Gaussian: which windows' objects it belongs to.
        let mut ids = std::collections::HashMap::<Vec<bool>, u32>::new();
        let classes: Vec<u32> = (0..n)
            .map(|i| {
                let signature: Vec<bool> = self.windows.iter().map(|w| w.mask[i] != 0.0).collect();
                let next = ids.len() as u32;
                *ids.entry(signature).or_insert(next)
            })
            .collect();
        if ids.len() > MAX_CLASSES {
            tracing::warn!(
                "`optimise_gaussians`: the queries' objects overlap in {} ways (at most \
                 {MAX_CLASSES} can be kept apart); the optimisation renders all {n} Gaussians",
                ids.len()
            );
            return Ok(());
        }
        let coarse = coarsen(&self.scene, &classes, budget)
            .context("`optimise_gaussians`: merging the scene")?;
        let masks = self
            .windows
            .iter()
            .map(|w| coarse.carry(&self.scene, &w.mask))
            .collect();
        self.derived.push(Derived {
            key: "optimise_gaussians",
            value: coarse.scene.len() as f64,
            why: format!(
                "the scene's {n} Gaussians, above {budget}: neighbours of the same objects \
                 merged in cells of {:.4} for the optimisation renders (metrics and frames \
                 render all of them)",
                coarse.cell
            ),
        });
        self.coarse = Some(CoarseCopy {
            scene: coarse.scene,
            masks,
        });
        Ok(())
    }

    /// The scene the optimisation passes render.
    pub fn optimisation_scene(&self) -> &Scene {
        self.coarse.as_ref().map_or(&self.scene, |c| &c.scene)
    }

    /// The windows with their masks over [`Experiment::optimisation_scene`].
    pub fn optimisation_windows(&self) -> Cow<'_, [WindowTarget]> {
        match &self.coarse {
            None => Cow::Borrowed(&self.windows),
            Some(c) => Cow::Owned(
                self.windows
                    .iter()
                    .zip(&c.masks)
                    .map(|(w, mask)| WindowTarget {
                        mask: mask.clone(),
                        ..w.clone()
                    })
                    .collect(),
            ),
        }
    }

    /// The optimisation scene on the autodiff device.
    pub fn autodiff_scene(&self) -> DeviceScene {
        let device = self.device.clone().autodiff();
        DeviceScene::new(self.optimisation_scene(), &device, self.dtype)
    }

    /// The optimisation scene on the plain device (the start search's renders): the plain
    /// scene, uploaded once, when there is no coarse copy.
    pub fn plain_optimisation_scene(&self) -> DeviceScene {
        match &self.coarse {
            None => self.plain_scene(),
            Some(c) => DeviceScene::new(&c.scene, &self.device, self.dtype),
        }
    }

    /// Window `i`'s object alone in the optimisation scene, on `device`: the one uploaded once
    /// ([`Experiment::object_alone`]) when that is the same scene on the same device.
    pub fn optimisation_alone(&self, i: usize, device: &Device) -> DeviceScene {
        let mask = match &self.coarse {
            None if *device == self.device => return self.object_alone(i),
            None => &self.windows[i].mask,
            Some(c) => &c.masks[i],
        };
        let keep: Vec<bool> = mask.iter().map(|&m| m != 0.0).collect();
        DeviceScene::new(&self.optimisation_scene().subset(&keep), device, self.dtype)
    }
}
