//! Sparse symmetric (Hermitian) positive definite systems, solved with faer's supernodal
//! sparse Cholesky.
//!
//! The work that depends only on which unknowns meet is done once: the fill-reducing order
//! once per graph, on its nodes ([`NodeOrder`]), whatever the unknowns per node; the symbolic
//! factorization (elimination tree, supernodes) once per pattern, shared by every system on it
//! ([`SparsePattern::sharing`]). The pattern is stored already permuted, and every value's
//! place in it is known, so a numeric factorization only scatters the values and factors: no
//! sorting, no permuting and no allocation per factorization.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::linalg::{SupernodalThreshold, amd};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::traits::ComplexField;
use faer::{Conj, MatMut, Par, Side};
use std::ops::AddAssign;
use std::sync::Arc;

pub use faer::c64;

/// A fill-reducing order of a graph's nodes: approximate minimum degree on the graph whose
/// edges are the pairs of nodes that share a measurement. Every system on that graph (a
/// pose's x, y, θ; a rotation's cosine and sine; a position) is ordered by it, its unknowns
/// kept together; a system that holds some nodes fixed keeps the others in the same order,
/// which fills in no more than the whole graph does.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NodeOrder {
    /// `place[i]`: the place of node i in the order.
    place: Vec<usize>,
}

impl NodeOrder {
    /// The order of `nodes` nodes linked by `links` (either way round, repeats allowed).
    pub fn new(nodes: usize, links: impl IntoIterator<Item = (usize, usize)>) -> NodeOrder {
        let mut pairs: Vec<(usize, usize)> = links
            .into_iter()
            .filter(|&(a, b)| a != b)
            .map(|(a, b)| (a.min(b), a.max(b)))
            .collect();
        pairs.sort_unstable();
        pairs.dedup();
        // The strict lower triangle: AMD orders A + Aᵀ and ignores the diagonal.
        let columns = CompressedColumns::of_pairs(nodes, &pairs);
        let graph =
            SymbolicSparseColMat::new_checked(nodes, nodes, columns.start, None, columns.rows);
        let (mut order, mut place) = (vec![0usize; nodes], vec![0usize; nodes]);
        let mut buffer = MemBuffer::new(amd::order_maybe_unsorted_scratch::<usize>(
            nodes,
            graph.compute_nnz(),
        ));
        amd::order_maybe_unsorted(
            &mut order,
            &mut place,
            graph.as_ref(),
            amd::Control::default(),
            MemStack::new(&mut buffer),
        )
        .expect("AMD ordering of a valid pattern");
        NodeOrder { place }
    }

    /// Nodes ordered.
    pub fn len(&self) -> usize {
        self.place.len()
    }

    /// True for the order of no nodes.
    pub fn is_empty(&self) -> bool {
        self.place.is_empty()
    }

    /// The places, in this order, of the nodes `kept` (each once, all below [`Self::len`]) among
    /// themselves: 0..kept.len().
    pub fn places_of(&self, kept: &[usize]) -> Vec<usize> {
        let mut at_place = vec![usize::MAX; self.place.len()];
        for (k, &node) in kept.iter().enumerate() {
            at_place[self.place[node]] = k;
        }
        let mut places = vec![0; kept.len()];
        for (rank, &k) in at_place.iter().filter(|&&k| k != usize::MAX).enumerate() {
            places[k] = rank;
        }
        places
    }
}

/// A block pattern's off-diagonal half, compressed: block column `c` holds the block rows
/// `rows[start[c]..start[c + 1]]`, increasing.
struct CompressedColumns {
    start: Vec<usize>,
    rows: Vec<usize>,
}

impl CompressedColumns {
    /// From sorted, distinct `(column, row)` pairs.
    fn of_pairs(columns: usize, pairs: &[(usize, usize)]) -> CompressedColumns {
        let mut start = vec![0; columns + 1];
        for &(column, _) in pairs {
            start[column + 1] += 1;
        }
        for c in 0..columns {
            start[c + 1] += start[c];
        }
        CompressedColumns {
            start,
            rows: pairs.iter().map(|&(_, row)| row).collect(),
        }
    }

    fn rows_of(&self, column: usize) -> &[usize] {
        &self.rows[self.start[column]..self.start[column + 1]]
    }

    /// The transpose: column `c` holds the columns whose rows hold `c`, increasing (the
    /// columns are walked in order, so no sort is needed).
    fn transposed(&self) -> CompressedColumns {
        let columns = self.start.len() - 1;
        let mut start = vec![0; columns + 1];
        for &row in &self.rows {
            start[row + 1] += 1;
        }
        for c in 0..columns {
            start[c + 1] += start[c];
        }
        let mut next = start.clone();
        let mut rows = vec![0; self.rows.len()];
        for column in 0..columns {
            for &row in self.rows_of(column) {
                rows[next[row]] = column;
                next[row] += 1;
            }
        }
        CompressedColumns { start, rows }
    }
}

/// What a pattern's systems share: its order, its values' places and its symbolic
/// factorization.
struct Shape {
    n: usize,
    /// `inverse[i]`: the place of unknown i in the fill-reducing order.
    inverse: Vec<usize>,
    /// The lower triangle of the permuted matrix.
    pattern: SymbolicSparseColMat<usize>,
    /// `slot[k]`: where the value of entry k goes in the values.
    slot: Vec<usize>,
    /// `transposed[k]`: entry k lies above the diagonal once permuted, so its value goes in
    /// as the lower triangle's conjugate (a complex matrix is Hermitian).
    transposed: Vec<bool>,
    symbolic: SymbolicCholesky<usize>,
}

impl Shape {
    /// The permuted lower triangle's values from the values in the order given.
    fn scatter<T: ComplexField + Copy + Default + AddAssign>(&self, values: &[T], out: &mut [T]) {
        out.fill(T::default());
        if T::IS_REAL {
            for (&slot, &value) in self.slot.iter().zip(values) {
                out[slot] += value;
            }
        } else {
            for ((&slot, &value), &transposed) in self.slot.iter().zip(values).zip(&self.transposed)
            {
                out[slot] += if transposed {
                    T::conj_impl(&value)
                } else {
                    value
                };
            }
        }
    }
}

/// A fixed sparsity pattern (lower triangle, duplicates summed) with its symbolic Cholesky,
/// and the storage of the last numeric factor of a system on it, of real (`f64`) or complex
/// Hermitian ([`c64`]) values.
pub struct SparsePattern<T = f64> {
    shape: Arc<Shape>,
    values: Vec<T>,
    factor: Vec<T>,
    factored: bool,
    /// Scratch of the numeric factorization and of a one-column solve.
    workspace: MemBuffer,
}

impl<T> std::fmt::Debug for SparsePattern<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparsePattern")
            .field("n", &self.shape.n)
            .field("values", &self.shape.slot.len())
            .field("factor_len", &self.factor.len())
            .finish()
    }
}

/// The numeric factorization failed: the matrix is not positive definite.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NotPositiveDefinite;

impl<T: ComplexField + Copy + Default + AddAssign> SparsePattern<T> {
    /// The pattern of a matrix of `block_place.len()` blocks of `block` unknowns (a pose's
    /// x, y, θ), block `b` at place `block_place[b]` of the elimination order
    /// ([`NodeOrder::places_of`]). `nonzero` lists its nonzero blocks, `(row, col)` with
    /// `row ≥ col` (duplicates summed), in the order their values will be given: a diagonal
    /// block its lower triangle row by row (`block·(block + 1)/2` values), any other block all
    /// its `block²` values row by row. The pattern is built on the graph of blocks, `block²`
    /// times smaller than the scalar one, and each block that holds an entry is kept whole.
    pub fn ordered(
        block: usize,
        nonzero: &[(usize, usize)],
        block_place: &[usize],
    ) -> SparsePattern<T> {
        assert!(block > 0, "blocks of one unknown or more");
        let blocks = block_place.len();
        let n = blocks * block;
        // The off-diagonal blocks, permuted, as (column, row) with column < row.
        let mut pairs: Vec<(usize, usize)> = nonzero
            .iter()
            .filter(|&&(row, col)| row != col)
            .map(|&(row, col)| {
                debug_assert!(row > col && row < blocks, "lower triangle only");
                let (a, b) = (block_place[row], block_place[col]);
                (a.min(b), a.max(b))
            })
            .collect();
        pairs.sort_unstable();
        pairs.dedup();
        let lower = CompressedColumns::of_pairs(blocks, &pairs);

        // The lower triangle, column by column: the rest of the diagonal block, then each
        // block below it whole.
        let mut col_ptr = Vec::with_capacity(n + 1);
        col_ptr.push(0);
        let mut row_idx = Vec::with_capacity(blocks * block * block + pairs.len() * block * block);
        for col in 0..blocks {
            for d in 0..block {
                row_idx.extend(col * block + d..(col + 1) * block);
                for &row in lower.rows_of(col) {
                    row_idx.extend(row * block..(row + 1) * block);
                }
                col_ptr.push(row_idx.len());
            }
        }
        let inverse: Vec<usize> = (0..n)
            .map(|i| block_place[i / block] * block + i % block)
            .collect();

        // Each value's place in the permuted lower triangle, and whether the permutation put
        // it above the diagonal (then it goes in transposed).
        let values = nonzero
            .iter()
            .map(|&(row, col)| {
                if row == col {
                    block * (block + 1) / 2
                } else {
                    block * block
                }
            })
            .sum();
        let mut slot = Vec::with_capacity(values);
        let mut transposed = Vec::with_capacity(values);
        for &(row, col) in nonzero {
            let (a, b) = (block_place[row], block_place[col]);
            if row == col {
                for r in 0..block {
                    slot.extend((0..=r).map(|c| col_ptr[a * block + c] + r - c));
                }
                transposed.resize(slot.len(), false);
                continue;
            }
            let (low, high) = (a.min(b), a.max(b));
            let k = lower
                .rows_of(low)
                .binary_search(&high)
                .expect("every nonzero block is in the pattern");
            // Below the diagonal, the value of (high + i, low + j) sits in column low + j,
            // after the rest of its diagonal block and k whole blocks.
            let place = |i: usize, j: usize| col_ptr[low * block + j] + block - j + k * block + i;
            for r in 0..block {
                if a > b {
                    slot.extend((0..block).map(|c| place(r, c)));
                } else {
                    slot.extend((0..block).map(|c| place(c, r)));
                }
            }
            transposed.resize(slot.len(), a < b);
        }

        // faer's symbolic analysis with the identity ordering reads the upper triangle
        // (whatever side it is told): the transpose, the blocks above the diagonal first.
        let upper_blocks = lower.transposed();
        let mut upper_ptr = Vec::with_capacity(n + 1);
        upper_ptr.push(0);
        let mut upper_idx = Vec::with_capacity(row_idx.len());
        for col in 0..blocks {
            for d in 0..block {
                for &row in upper_blocks.rows_of(col) {
                    upper_idx.extend(row * block..(row + 1) * block);
                }
                upper_idx.extend(col * block..=col * block + d);
                upper_ptr.push(upper_idx.len());
            }
        }
        let upper = SymbolicSparseColMat::new_checked(n, n, upper_ptr, None, upper_idx);
        // Blocks of poses fill in: there the supernodal (blocked, dense-kernel)
        // factorization is several times faster than the simplicial one faer's heuristic
        // picks. One unknown per node (the chordal initialization's systems) factors faster
        // simplicial (manhattan 4.5 against 6.4 ms, city10000 22 against 24 ms).
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: if block > 1 {
                SupernodalThreshold::FORCE_SUPERNODAL
            } else {
                SupernodalThreshold::FORCE_SIMPLICIAL
            },
            ..Default::default()
        };
        let symbolic = factorize_symbolic_cholesky(
            upper.as_ref(),
            Side::Upper,
            SymmetricOrdering::Identity,
            params,
        )
        .expect("symbolic Cholesky of a valid pattern");
        SparsePattern::on(Arc::new(Shape {
            n,
            inverse,
            pattern: SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx),
            slot,
            transposed,
            symbolic,
        }))
    }

    fn on(shape: Arc<Shape>) -> SparsePattern<T> {
        let workspace = MemBuffer::new(StackReq::any_of(&[
            shape
                .symbolic
                .factorize_numeric_llt_scratch::<T>(Par::Seq, Default::default()),
            shape.symbolic.solve_in_place_scratch::<T>(1, Par::Seq),
        ]));
        SparsePattern {
            factor: vec![T::default(); shape.symbolic.len_val()],
            values: vec![T::default(); shape.pattern.compute_nnz()],
            shape,
            factored: false,
            workspace,
        }
    }

    /// Another system on the same pattern, of values of type `U`: the order and the symbolic
    /// factorization are shared, the values and the factor its own.
    pub fn sharing<U: ComplexField + Copy + Default + AddAssign>(&self) -> SparsePattern<U> {
        SparsePattern::on(Arc::clone(&self.shape))
    }

    /// The matrix's dimension (rows = columns).
    pub fn dim(&self) -> usize {
        self.shape.n
    }

    /// Factorizes the matrix with these `values` (block by block, as [`Self::ordered`] lists them),
    /// keeping the factor for [`Self::solve`]. A complex matrix is Hermitian: an entry
    /// `(row, col)` below the diagonal holds `A[row][col]`, and `A[col][row]` is its conjugate.
    pub fn factorize(&mut self, values: &[T]) -> Result<(), NotPositiveDefinite> {
        assert_eq!(
            values.len(),
            self.shape.slot.len(),
            "one value per pattern entry"
        );
        self.shape.scatter(values, &mut self.values);
        let matrix = SparseColMatRef::new(self.shape.pattern.as_ref(), &self.values);
        self.factored = false;
        self.shape
            .symbolic
            .factorize_numeric_llt::<T>(
                &mut self.factor,
                matrix,
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
    pub fn solve(&mut self, b: &[T]) -> Vec<T> {
        self.solve_columns(b, 1)
    }

    /// Solves A X = B for the `columns` right-hand sides in `b` (column-major, `dim()` rows
    /// each) at once with the last factor; X in the same layout.
    ///
    /// # Panics
    /// If the last [`Self::factorize`] did not succeed, or `b` is not `columns` columns.
    pub fn solve_columns(&mut self, b: &[T], columns: usize) -> Vec<T> {
        assert!(self.factored, "solve needs a successful factorize");
        let n = self.shape.n;
        assert_eq!(b.len(), n * columns, "columns of dim() values");
        let mut permuted = vec![T::default(); b.len()];
        for (out, col) in permuted.chunks_mut(n).zip(b.chunks(n)) {
            for (&place, &value) in self.shape.inverse.iter().zip(col) {
                out[place] = value;
            }
        }
        // One column fits the kept workspace; more need their own scratch.
        let mut wide = (columns > 1).then(|| {
            MemBuffer::new(
                self.shape
                    .symbolic
                    .solve_in_place_scratch::<T>(columns, Par::Seq),
            )
        });
        LltRef::new(&self.shape.symbolic, &self.factor).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut permuted, n, columns),
            Par::Seq,
            MemStack::new(wide.as_mut().unwrap_or(&mut self.workspace)),
        );
        let mut x = vec![T::default(); b.len()];
        for (out, col) in x.chunks_mut(n).zip(permuted.chunks(n)) {
            for (o, &place) in out.iter_mut().zip(&self.shape.inverse) {
                *o = col[place];
            }
        }
        x
    }
}

impl SparsePattern<f64> {
    /// A x for the symmetric matrix of these `values` (in the order given, as to
    /// [`Self::factorize`]).
    pub fn multiply(&self, values: &[f64], x: &[f64]) -> Vec<f64> {
        assert_eq!(
            values.len(),
            self.shape.slot.len(),
            "one value per pattern entry"
        );
        let shape = &self.shape;
        let mut lower = vec![0.0; shape.pattern.compute_nnz()];
        shape.scatter(values, &mut lower);
        let mut permuted = vec![0.0; shape.n];
        for (&place, &value) in shape.inverse.iter().zip(x) {
            permuted[place] = value;
        }
        let x = permuted;
        let mut y = vec![0.0; shape.n];
        let rows = shape.pattern.row_idx();
        for col in 0..shape.n {
            for k in shape.pattern.col_range(col) {
                let (row, value) = (rows[k], lower[k]);
                y[row] += value * x[col];
                if row != col {
                    y[col] += value * x[row];
                }
            }
        }
        shape.inverse.iter().map(|&place| y[place]).collect()
    }
}

#[cfg(test)]
mod tests;
