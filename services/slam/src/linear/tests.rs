//! The sparse systems against dense solves, the Hermitian case and the node order.

use super::*;

/// Solves A x = b once, for A given as nonzero blocks with their values (as
/// [`SparsePattern::ordered`] takes them), ordered by AMD on its blocks; x and A x.
fn solve_blocks(
    block: usize,
    nonzero: &[((usize, usize), Vec<f64>)],
    b: &[f64],
) -> Result<(Vec<f64>, Vec<f64>), NotPositiveDefinite> {
    let pairs: Vec<(usize, usize)> = nonzero.iter().map(|&(pair, _)| pair).collect();
    let order = NodeOrder::new(b.len() / block, pairs.iter().copied());
    let mut pattern: SparsePattern = SparsePattern::ordered(
        block,
        &pairs,
        &order.places_of(&(0..order.len()).collect::<Vec<_>>()),
    );
    let values: Vec<f64> = nonzero
        .iter()
        .flat_map(|(_, v)| v.iter().copied())
        .collect();
    pattern.factorize(&values)?;
    let x = pattern.solve(b);
    let product = pattern.multiply(&values, &x);
    Ok((x, product))
}

#[test]
fn solves_a_small_system_with_duplicates() {
    // [[4, 1], [1, 3]] given with the (0,0) entry split in two.
    let x = solve_blocks(
        1,
        &[
            ((0, 0), vec![3.0]),
            ((0, 0), vec![1.0]),
            ((1, 0), vec![1.0]),
            ((1, 1), vec![3.0]),
        ],
        &[1.0, 2.0],
    )
    .unwrap()
    .0;
    assert!((4.0 * x[0] + x[1] - 1.0).abs() < 1e-12 && (x[0] + 3.0 * x[1] - 2.0).abs() < 1e-12);
    assert_eq!(
        solve_blocks(1, &[((0, 0), vec![-1.0])], &[1.0]).err(),
        Some(NotPositiveDefinite)
    );
}

/// A Hermitian system on a real one's pattern, its unknowns in both orders (the entry
/// below the diagonal goes in conjugated when the order puts it above).
#[test]
fn a_hermitian_system_shares_the_real_ones_pattern() {
    // [[2, 1 − i], [1 + i, 3]]: the entry below the diagonal is A[1][0] = 1 + i.
    for places in [[0, 1], [1, 0]] {
        let real: SparsePattern = SparsePattern::ordered(1, &[(0, 0), (1, 0), (1, 1)], &places);
        let mut complex: SparsePattern<c64> = real.sharing();
        let a10 = c64::new(1.0, 1.0);
        complex
            .factorize(&[c64::new(2.0, 0.0), a10, c64::new(3.0, 0.0)])
            .unwrap();
        let b = [c64::new(1.0, 2.0), c64::new(-1.0, 0.5)];
        let x = complex.solve(&b);
        let row0 = c64::new(2.0, 0.0) * x[0] + a10.conj() * x[1];
        let row1 = a10 * x[0] + c64::new(3.0, 0.0) * x[1];
        assert!(
            (row0 - b[0]).norm() < 1e-12 && (row1 - b[1]).norm() < 1e-12,
            "places {places:?}"
        );
    }
}

#[test]
fn a_subset_of_nodes_keeps_their_order() {
    // A path 0 – 1 – 2 – 3 – 4: whatever AMD picks, the kept nodes keep its order.
    let order = NodeOrder::new(5, (0..4).map(|i| (i, i + 1)));
    let kept = [4, 1, 3];
    let places = order.places_of(&kept);
    let mut sorted = places.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, vec![0, 1, 2]);
    for (a, b) in [(0, 1), (0, 2), (1, 2)] {
        assert_eq!(
            places[a] < places[b],
            order.place[kept[a]] < order.place[kept[b]]
        );
    }
}

/// Random sparse block systems against the dense solve of the same matrix.
#[test]
fn block_systems_agree_with_dense_solves() {
    let mut rng = crate::splitmix::SplitMix::new(7);
    for block in [1usize, 2, 3] {
        let blocks = 12;
        let n = blocks * block;
        let mut dense = nalgebra::DMatrix::<f64>::zeros(n, n);
        let mut nonzero = Vec::new();
        for _ in 0..20 {
            let (a, b) = (
                (rng.unit() * blocks as f64) as usize,
                (rng.unit() * blocks as f64) as usize,
            );
            if a == b {
                continue;
            }
            let (hi, lo) = (a.max(b), a.min(b));
            let mut values = Vec::new();
            for r in 0..block {
                for c in 0..block {
                    let v = rng.unit() - 0.5;
                    dense[(hi * block + r, lo * block + c)] += v;
                    dense[(lo * block + c, hi * block + r)] += v;
                    values.push(v);
                }
            }
            nonzero.push(((hi, lo), values));
        }
        for d in 0..blocks {
            let mut values = Vec::new();
            for r in 0..block {
                for c in 0..=r {
                    let v = if r == c {
                        2.0 * n as f64
                    } else {
                        rng.unit() - 0.5
                    };
                    dense[(d * block + r, d * block + c)] += v;
                    if r != c {
                        dense[(d * block + c, d * block + r)] += v;
                    }
                    values.push(v);
                }
            }
            nonzero.push(((d, d), values));
        }
        let b: Vec<f64> = (0..n).map(|_| rng.unit()).collect();
        let (x, product) = solve_blocks(block, &nonzero, &b).unwrap();
        let ax = &dense * nalgebra::DVector::from_column_slice(&x);
        for i in 0..n {
            assert!(
                (ax[i] - b[i]).abs() < 1e-9,
                "block {block}: row {i}: {} vs {}",
                ax[i],
                b[i]
            );
            assert!(
                (product[i] - b[i]).abs() < 1e-9,
                "block {block}: A x, row {i}"
            );
        }
    }
}
