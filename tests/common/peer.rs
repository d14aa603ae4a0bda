//! Comparisons of rendered batches with a peer reference (a mean and the variance of that mean
//! per element, tests/data/*_peer): z-scores of group means (image means per channel, 8x8-pixel
//! blocks, transient bins), where our variance comes from independent batches and a z-score
//! divides a difference by the combined standard error of both sides.

use gatetrace::film::Film;

use super::stats::{sidak, t_critical};

/// Family-wise false-alarm rate of every multi-comparison.
pub const ALPHA: f64 = 0.01;

/// Per-element mean over batches, as f32 (for failure images).
pub fn batch_mean(films: &[Film]) -> Vec<f32> {
    let mut stats = super::stats::BatchStats::new(films[0].data.len());
    for f in films {
        stats.add(&f.data);
    }
    stats.mean().iter().map(|&v| v as f32).collect()
}

/// Sums over groups of elements: `group(i)` gives the group of element i (None: skip).
pub fn group_sums(values: &[f64], groups: usize, group: impl Fn(usize) -> Option<usize>) -> Vec<f64> {
    let mut out = vec![0.0; groups];
    for (i, v) in values.iter().enumerate() {
        if let Some(g) = group(i) {
            out[g] += v;
        }
    }
    out
}

/// Compares group means (the image mean per channel, or block means) of our batches with the
/// peer's; returns the z-scores. The variance of a group mean is the variance over batches of
/// the group's batch means (so pixel correlations are included); the peer's variance of a group
/// mean adds its per-pixel variances (independent pixels).
pub fn group_z(
    films: &[Film],
    peer_mean: &[f32],
    peer_var: &[f32],
    groups: usize,
    group: impl Fn(usize) -> Option<usize> + Copy,
) -> Vec<(f64, f64, f64)> {
    let n = films.len() as f64;
    let count = group_sums(&vec![1.0; peer_mean.len()], groups, group);
    let ours: Vec<Vec<f64>> = films
        .iter()
        .map(|f| {
            let data: Vec<f64> = f.data.iter().map(|&v| v as f64).collect();
            group_sums(&data, groups, group).iter().zip(&count).map(|(s, c)| s / c).collect()
        })
        .collect();
    let peer: Vec<f64> = group_sums(&peer_mean.iter().map(|&v| v as f64).collect::<Vec<_>>(), groups, group)
        .iter()
        .zip(&count)
        .map(|(s, c)| s / c)
        .collect();
    let peer_v: Vec<f64> = group_sums(&peer_var.iter().map(|&v| v as f64).collect::<Vec<_>>(), groups, group)
        .iter()
        .zip(&count)
        .map(|(s, c)| s / (c * c))
        .collect();
    (0..groups)
        .map(|g| {
            let mean = ours.iter().map(|o| o[g]).sum::<f64>() / n;
            let var = ours.iter().map(|o| (o[g] - mean).powi(2)).sum::<f64>() / (n - 1.0) / n;
            let z = (mean - peer[g]) / (var + peer_v[g]).sqrt().max(1e-300);
            (mean, peer[g], z)
        })
        .collect()
}

/// Compares an image with the peer's `{reference}_mean.npy` (and `_var`): see
/// [`check_image_values`].
pub fn check_image(name: &str, films: &[Film], reference: &str) {
    let (shape, peer_mean) = super::reference(&format!("{reference}_mean.npy"));
    let (_, peer_var) = super::reference(&format!("{reference}_var.npy"));
    check_image_values(name, films, &shape, &peer_mean, &peer_var);
}

/// Compares an image ([H, W, 3], H and W multiples of 8) with the peer's mean and the variance of
/// that mean per element: the image mean per channel (|z| < 4) and 8x8-pixel blocks per channel
/// (Sidak-corrected).
pub fn check_image_values(name: &str, films: &[Film], shape: &[usize], peer_mean: &[f32], peer_var: &[f32]) {
    assert!(
        shape.len() == 3 && shape[2] == 3 && shape[0].is_multiple_of(8) && shape[1].is_multiple_of(8),
        "{name}: {shape:?}"
    );
    let (width, height) = (shape[1], shape[0]);
    let write_failure =
        || super::write_failure_images(name, shape, &batch_mean(films), peer_mean).display().to_string();
    // Image mean per channel: |z| < 4 (the acceptance criterion).
    let channel = group_z(films, peer_mean, peer_var, 3, |i| Some(i % 3));
    for (c, (ours, peer, z)) in channel.iter().enumerate() {
        println!("{name} channel {c}: ours {ours:.6} peer {peer:.6} z {z:+.2}");
        if z.abs() >= 4.0 {
            panic!("{name}: channel {c} mean {ours} vs peer {peer}, z = {z:.2}; images in {}", write_failure());
        }
    }
    // 8x8-pixel blocks per channel (192 comparisons at 64x64), Sidak-corrected.
    let columns = width / 8;
    let blocks = group_z(films, peer_mean, peer_var, 3 * columns * (height / 8), |i| {
        let (p, c) = (i / 3, i % 3);
        let (x, y) = (p % width, p / width);
        Some(((y / 8) * columns + x / 8) * 3 + c)
    });
    let limit = t_critical(sidak(ALPHA, blocks.len()), (films.len() - 1) as f64);
    let (at, worst) =
        blocks.iter().enumerate().map(|(i, b)| (i, b.2.abs())).fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    let (ours, peer) = (blocks[at].0, blocks[at].1);
    println!(
        "{name}: worst block |z| {worst:.2} (limit {limit:.2}): block row {}, column {}, channel {}: ours {ours:.6}, peer {peer:.6}",
        at / 3 / columns,
        at / 3 % columns,
        at % 3
    );
    if worst >= limit {
        panic!("{name}: a block differs from the peer (|z| = {worst:.2} >= {limit:.2}); images in {}", write_failure());
    }
}

/// Compares a transient cube of `bins` bins with the peer's `{reference}_mean.npy` (and
/// `_var`): the image mean of every bin and channel, Sidak-corrected. Returns the z-scores
/// (ours, peer, z) per bin and channel.
pub fn check_transient(name: &str, films: &[Film], reference: &str, bins: usize) -> Vec<(f64, f64, f64)> {
    let (shape, peer_mean) = super::reference(&format!("{reference}_mean.npy"));
    let (_, peer_var) = super::reference(&format!("{reference}_var.npy"));
    assert_eq!(shape[2..], [bins, 3]);
    let groups = 3 * bins;
    let z = group_z(films, &peer_mean, &peer_var, groups, |i| Some(i % groups));
    let limit = t_critical(sidak(ALPHA, z.len()), (films.len() - 1) as f64);
    for (g, (ours, peer, score)) in z.iter().enumerate() {
        if score.abs() >= limit {
            let dir = super::write_failure_images(name, &shape, &batch_mean(films), &peer_mean);
            panic!(
                "{name}: bin {} channel {}: {ours} vs peer {peer} (z = {score:.2}, limit {limit:.2}); images in {}",
                g / 3,
                g % 3,
                dir.display()
            );
        }
    }
    z
}
