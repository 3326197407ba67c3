//! A parallel map over a pass's poses that starts the heaviest first and keeps the poses'
//! order in its results.
//!
//! Why: a step's poses differ several-fold (a wide shot's against a close-up's), and one of
//! the largest started last keeps the other cores waiting (first-try guitar on 2 cores:
//! binning 17.0 → 14.5 ms for 26.5 ms of work; the row layout 2.32 → 2.21 ms).

use std::cmp::Reverse;

use rayon::prelude::*;

/// `f` of each item on rayon's pool, the items of largest `weight` handed out first (ties in
/// their order), the results in the items' order.
pub fn map_heaviest_first<T: Send, R: Send>(
    items: Vec<T>,
    weight: impl Fn(&T) -> usize,
    f: impl Fn(T) -> R + Sync + Send,
) -> Vec<R> {
    let mut started: Vec<(usize, T)> = items.into_iter().enumerate().collect();
    started.sort_by_key(|(_, item)| Reverse(weight(item)));
    let mut done: Vec<(usize, R)> = started
        .into_par_iter()
        .map(|(i, item)| (i, f(item)))
        .collect();
    done.sort_unstable_by_key(|&(i, _)| i);
    done.into_iter().map(|(_, r)| r).collect()
}

#[cfg(test)]
mod tests {
    use super::map_heaviest_first;

    #[test]
    fn results_come_in_the_items_order() {
        let items: Vec<usize> = vec![3, 40, 1, 40, 7, 0];
        let doubled = map_heaviest_first(items.clone(), |&w| w, |w| 2 * w);
        assert_eq!(doubled, items.iter().map(|w| 2 * w).collect::<Vec<_>>());
        assert!(map_heaviest_first(Vec::<usize>::new(), |&w| w, |w| w).is_empty());
    }
}
