//! Sparse symmetric positive definite systems, solved with faer's supernodal sparse Cholesky.
//! The symbolic factorization (AMD ordering, elimination tree, supernodes) is computed once
//! per sparsity pattern; every numeric factorization with that pattern reuses it, and the
//! factor's storage and workspace are kept between factorizations.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::perm::PermRef;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::linalg::{SupernodalThreshold, amd};
use faer::sparse::{Argsort, Pair, SparseColMat, SymbolicSparseColMat};
use faer::{Conj, Mat, Par, Side};

/// A fixed sparsity pattern (lower triangle, duplicates summed) with its symbolic Cholesky,
/// and the storage of the last numeric factor.
pub struct SparsePattern {
    n: usize,
    entries: Vec<(usize, usize)>,
    pattern: SymbolicSparseColMat<usize>,
    argsort: Argsort<usize>,
    symbolic: SymbolicCholesky<usize>,
    factor: Vec<f64>,
    factored: bool,
    workspace: MemBuffer,
}

impl std::fmt::Debug for SparsePattern {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparsePattern")
            .field("n", &self.n)
            .field("entries", &self.entries.len())
            .field("factor_len", &self.factor.len())
            .finish()
    }
}

/// The numeric factorization failed: the matrix is not positive definite.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NotPositiveDefinite;

impl SparsePattern {
    /// The pattern of an `n`×`n` matrix whose lower-triangle entries are `(row, col)` pairs,
    /// in the order their values will be given; duplicates are summed.
    pub fn new(n: usize, entries: &[(usize, usize)]) -> SparsePattern {
        SparsePattern::new_blocked(n, entries, 1)
    }

    /// Like [`Self::new`] for unknowns in blocks of `block` (a pose's x, y, θ): the
    /// fill-reducing ordering is computed on the graph of blocks, `block²` times smaller, and
    /// keeps each block's unknowns together.
    pub fn new_blocked(n: usize, entries: &[(usize, usize)], block: usize) -> SparsePattern {
        let pairs: Vec<Pair<usize, usize>> = entries
            .iter()
            .map(|&(row, col)| {
                debug_assert!(row >= col, "lower triangle only");
                Pair { row, col }
            })
            .collect();
        let (pattern, argsort) = SymbolicSparseColMat::try_new_from_indices(n, n, &pairs)
            .expect("indices within the matrix");
        // Pose graphs fill in: the supernodal (blocked, dense-kernel) factorization is several
        // times faster than the simplicial one faer's heuristic picks for them.
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
            ..Default::default()
        };
        let (perm, perm_inv) = block_amd(n, entries, block);
        let ordering = SymmetricOrdering::Custom(PermRef::new_checked(&perm, &perm_inv, n));
        let symbolic = factorize_symbolic_cholesky(pattern.as_ref(), Side::Lower, ordering, params)
            .expect("symbolic Cholesky of a valid pattern");
        let workspace = MemBuffer::new(StackReq::any_of(&[
            symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(1, Par::Seq),
        ]));
        let factor = vec![0.0; symbolic.len_val()];
        SparsePattern {
            n,
            entries: entries.to_vec(),
            pattern,
            argsort,
            symbolic,
            factor,
            factored: false,
            workspace,
        }
    }

    pub fn dim(&self) -> usize {
        self.n
    }

    /// The `(row, col)` entries, in the order values are given.
    pub fn entries(&self) -> &[(usize, usize)] {
        &self.entries
    }

    /// Factorizes the matrix with these `values` (one per entry given to [`Self::new`]),
    /// keeping the factor for [`Self::solve`].
    pub fn factorize(&mut self, values: &[f64]) -> Result<(), NotPositiveDefinite> {
        let matrix = SparseColMat::new_from_argsort(self.pattern.clone(), &self.argsort, values)
            .expect("one value per pattern entry");
        self.factored = false;
        self.symbolic
            .factorize_numeric_llt::<f64>(
                &mut self.factor,
                matrix.as_ref(),
                Side::Lower,
                LltRegularization::default(),
                Par::Seq,
                MemStack::new(&mut self.workspace),
                Default::default(),
            )
            .map_err(|_| NotPositiveDefinite)?;
        self.factored = true;
        Ok(())
    }

    /// Solves A x = b with the last factor.
    ///
    /// # Panics
    /// If the last [`Self::factorize`] did not succeed.
    pub fn solve(&mut self, b: &[f64]) -> Vec<f64> {
        assert!(self.factored, "solve needs a successful factorize");
        let mut rhs = Mat::from_fn(self.n, 1, |i, _| b[i]);
        LltRef::new(&self.symbolic, &self.factor).solve_in_place_with_conj(
            Conj::No,
            rhs.as_mut(),
            Par::Seq,
            MemStack::new(&mut self.workspace),
        );
        (0..self.n).map(|i| rhs[(i, 0)]).collect()
    }
}

/// Approximate minimum degree ordering of the block graph, expanded to the unknowns:
/// (forward, inverse) permutations of 0..n.
fn block_amd(n: usize, entries: &[(usize, usize)], block: usize) -> (Vec<usize>, Vec<usize>) {
    assert!(
        block > 0 && n.is_multiple_of(block),
        "unknowns come in whole blocks"
    );
    let blocks = n / block;
    // Every block holds its top-left entry: one pair per block suffices.
    let pairs: Vec<Pair<usize, usize>> = entries
        .iter()
        .filter(|&&(r, c)| r.is_multiple_of(block) && c.is_multiple_of(block))
        .map(|&(r, c)| Pair {
            row: r / block,
            col: c / block,
        })
        .collect();
    let (graph, _) =
        SymbolicSparseColMat::try_new_from_indices(blocks, blocks, &pairs).expect("block indices");
    let (mut fwd, mut inv) = (vec![0usize; blocks], vec![0usize; blocks]);
    let nnz = graph.compute_nnz();
    let mut buffer = MemBuffer::new(amd::order_maybe_unsorted_scratch::<usize>(blocks, nnz));
    amd::order_maybe_unsorted(
        &mut fwd,
        &mut inv,
        graph.as_ref(),
        amd::Control::default(),
        MemStack::new(&mut buffer),
    )
    .expect("AMD ordering of a valid pattern");
    let expand = |p: &[usize]| -> Vec<usize> {
        p.iter()
            .flat_map(|&b| (0..block).map(move |d| b * block + d))
            .collect()
    };
    (expand(&fwd), expand(&inv))
}

/// Solves A x = b once, for A given as lower-triangle triplets (duplicates summed), with
/// unknowns in blocks of `block`.
pub fn solve_once(
    n: usize,
    block: usize,
    triplets: &[(usize, usize, f64)],
    b: &[f64],
) -> Result<Vec<f64>, NotPositiveDefinite> {
    let entries: Vec<(usize, usize)> = triplets.iter().map(|&(r, c, _)| (r, c)).collect();
    let values: Vec<f64> = triplets.iter().map(|t| t.2).collect();
    let mut pattern = SparsePattern::new_blocked(n, &entries, block);
    pattern.factorize(&values)?;
    Ok(pattern.solve(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_small_system_with_duplicates() {
        // [[4, 1], [1, 3]] given with the (0,0) entry split in two.
        let x = solve_once(
            2,
            1,
            &[(0, 0, 3.0), (0, 0, 1.0), (1, 0, 1.0), (1, 1, 3.0)],
            &[1.0, 2.0],
        )
        .unwrap();
        assert!((4.0 * x[0] + x[1] - 1.0).abs() < 1e-12 && (x[0] + 3.0 * x[1] - 2.0).abs() < 1e-12);
        assert_eq!(
            solve_once(1, 1, &[(0, 0, -1.0)], &[1.0]).err(),
            Some(NotPositiveDefinite)
        );
    }
}
