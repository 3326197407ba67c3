//! Occlusion IoU (a metric): how much of the object's bounding box the rest of the scene hides.
//!
//! IoU = |B_vis ∩ B_alone| / |B_vis ∪ B_alone| between the pixel bounding box of the object's
//! visible mask (composited with every Gaussian, so occluders lower it) and that of the object
//! rendered alone (all other Gaussians removed) from the same pose (docs/conventions.md "Metrics").
//! A pixel belongs to a mask when its value is ≥ [`IOU_THRESHOLD`]. 1 when nothing hides the
//! object; a box half hidden along one side gives ½.
//!
//! **Empty boxes.** When neither mask has a pixel at the threshold (the object is out of view,
//! or too thin or transparent to cover half a pixel) the IoU is defined as **0**, not 1: the
//! metric rewards seeing the object unhidden, and a view without the object shows nothing of it.
//! When only one box is empty the union is non-empty and the intersection empty, so it is 0 too.
//! The result is never NaN.
//!
//! It is not a [`super::Cost`]: boxes are piecewise constant in the pose (no useful gradient;
//! the paper reports that optimising IoU directly makes gradient steps jump, its §V), and it
//! needs a second render (the object alone), which the optimisation loop does not make. So it
//! is host code, called on the final renders.

use burn::tensor::Tensor;

/// A pixel belongs to a mask when its value is at least this (docs/conventions.md: threshold 0.5).
pub const IOU_THRESHOLD: f64 = 0.5;

/// A pixel bounding box, half-open: columns `x0..x1`, rows `y0..y1` (never empty).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelBox {
    /// First column.
    pub x0: usize,
    /// First row.
    pub y0: usize,
    /// One past the last column.
    pub x1: usize,
    /// One past the last row.
    pub y1: usize,
}

impl PixelBox {
    /// Number of pixels inside.
    pub fn area(&self) -> usize {
        (self.x1 - self.x0) * (self.y1 - self.y0)
    }

    /// The overlap of two boxes, if any.
    pub fn intersection(&self, other: &PixelBox) -> Option<PixelBox> {
        let b = PixelBox {
            x0: self.x0.max(other.x0),
            y0: self.y0.max(other.y0),
            x1: self.x1.min(other.x1),
            y1: self.y1.min(other.y1),
        };
        (b.x0 < b.x1 && b.y0 < b.y1).then_some(b)
    }
}

/// Bounding box of the pixels ≥ `threshold` of a row-major `[height, width]` mask; None if none.
///
/// # Panics
/// If `mask.len() != width * height`.
pub fn mask_box(mask: &[f64], width: usize, height: usize, threshold: f64) -> Option<PixelBox> {
    assert_eq!(mask.len(), width * height, "mask is not {height}×{width}");
    let mut found: Option<PixelBox> = None;
    for (j, row) in mask.chunks_exact(width.max(1)).enumerate() {
        for (i, &v) in row.iter().enumerate() {
            if v >= threshold {
                let b = found.get_or_insert(PixelBox {
                    x0: i,
                    y0: j,
                    x1: i + 1,
                    y1: j + 1,
                });
                b.x0 = b.x0.min(i);
                b.x1 = b.x1.max(i + 1);
                b.y0 = b.y0.min(j);
                b.y1 = b.y1.max(j + 1);
            }
        }
    }
    found
}

/// Bounding-box IoU of the visible mask and the object-alone mask, both row-major
/// `[height, width]`, thresholded at [`IOU_THRESHOLD`]; 0 when both boxes are empty (module docs).
///
/// # Panics
/// If either mask's length is not `width * height`.
pub fn bbox_iou(visible: &[f64], alone: &[f64], width: usize, height: usize) -> f64 {
    box_iou(
        mask_box(visible, width, height, IOU_THRESHOLD),
        mask_box(alone, width, height, IOU_THRESHOLD),
    )
}

/// IoU of two boxes; 0 when either is empty (module docs).
pub fn box_iou(a: Option<PixelBox>, b: Option<PixelBox>) -> f64 {
    match (a, b) {
        (Some(a), Some(b)) => {
            let inter = a.intersection(&b).map_or(0, |i| i.area());
            let union = a.area() + b.area() - inter;
            inter as f64 / union as f64
        }
        // One or both empty: no overlap (both empty is defined as 0, see module docs).
        _ => 0.0,
    }
}

/// Which rows `[B, H]` and columns `[B, W]` of masks `[B, H, W]` hold a pixel at or above
/// `threshold` (1 or 0), computed where the masks are: the boxes need H + W values a mask read
/// back instead of H·W ([`box_from_hits`]).
pub fn mask_hits(masks: Tensor<3>, threshold: f64) -> (Tensor<2>, Tensor<2>) {
    let [batch, height, width] = masks.dims();
    let dtype = masks.dtype();
    let on = masks.greater_equal_elem(threshold).float().cast(dtype); // [B, H, W]
    let rows = on.clone().max_dim(2).reshape([batch, height]);
    let columns = on.max_dim(1).reshape([batch, width]);
    (rows, columns)
}

/// The box of a mask from its row and column hits ([`mask_hits`], nonzero = hit); None when no
/// row has one. The same box as [`mask_box`] of the mask.
pub fn box_from_hits(rows: &[f64], columns: &[f64]) -> Option<PixelBox> {
    let span = |hits: &[f64]| {
        let first = hits.iter().position(|&h| h != 0.0)?;
        let last = hits.iter().rposition(|&h| h != 0.0)?;
        Some((first, last + 1))
    };
    let ((y0, y1), (x0, x1)) = (span(rows)?, span(columns)?);
    Some(PixelBox { x0, y0, x1, y1 })
}

/// [`bbox_iou`] per sample for batches of masks `[B, H, W]` (boxes found on the device, their
/// hits read back; no gradient).
///
/// # Panics
/// If the two batches' shapes differ, or the hits cannot be read back.
pub fn bbox_iou_batch(visible: Tensor<3>, alone: Tensor<3>) -> Vec<f64> {
    let dims = visible.dims();
    assert_eq!(
        dims,
        alone.dims(),
        "visible and alone masks differ in shape"
    );
    let [batch, height, width] = dims;
    let boxes = |t: Tensor<3>| -> Vec<Option<PixelBox>> {
        let (rows, columns) = mask_hits(t, IOU_THRESHOLD);
        let host = |t: Tensor<2>| {
            splatraj_render::host::to_host(t).expect("float tensor data converts to f64")
        };
        let (rows, columns) = (host(rows), host(columns));
        (0..batch)
            .map(|b| {
                box_from_hits(
                    &rows[b * height..(b + 1) * height],
                    &columns[b * width..(b + 1) * width],
                )
            })
            .collect()
    };
    boxes(visible)
        .into_iter()
        .zip(boxes(alone))
        .map(|(v, a)| box_iou(v, a))
        .collect()
}
