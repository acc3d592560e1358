"""Sparse LDLᵀ of a symmetric positive definite matrix in a given elimination order, in
numba: the up-looking algorithm of Davis's LDL (T. A. Davis, "Algorithm 849: A concise sparse
Cholesky factorization package", ACM TOMS 31(4), 2005). Row k of L is the solution of a
triangular system whose pattern is the reach of column k's entries in the elimination tree,
so no supernodes and no pivoting: the factor costs its arithmetic and a scatter a row.

The global steps (core/projective.py) factor each mesh's system for every pin set and
sub-step length; the order comes from the first factor of the mesh (SuperLU's minimum
degree) and is kept, so a factor after a grip or a sub-step length change is the numeric
work alone (65²: 2.5 ms for the springs' system against SuperLU's 11.8; docs/solver.md).
"""
from __future__ import annotations

import numpy as np
from numba import njit
import scipy.sparse as sparse


@njit(cache=True)
def _elimination_tree(pointer, index, parent):
    """The elimination tree (``parent``, -1 at a root) of the symmetric matrix whose full
    pattern is the CSC (pointer, index), and the entries of each column of L below its
    diagonal (returned as L's column pointer)."""
    count = pointer.shape[0] - 1
    flag = np.empty(count, dtype=np.int64)
    column_entries = np.zeros(count, dtype=np.int64)
    for k in range(count):
        parent[k] = -1
        flag[k] = k
        for p in range(pointer[k], pointer[k + 1]):
            i = index[p]
            if i < k:
                # follow the path from i up the tree to the first node row k reached
                while flag[i] != k:
                    if parent[i] == -1:
                        parent[i] = k
                    column_entries[i] += 1  # L[k, i] is an entry
                    flag[i] = k
                    i = parent[i]
    column_pointer = np.zeros(count + 1, dtype=np.uint32)
    for k in range(count):
        column_pointer[k + 1] = column_pointer[k] + column_entries[k]
    return column_pointer


@njit(cache=True)
def _factor_rows(pointer, index, value, parent, column_pointer, row_index, lower, diagonal):
    """L (unit diagonal, strictly lower part in CSC with each column's rows ascending) and D
    of P A Pᵀ = L D Lᵀ, row by row. Returns the matrix's order if every pivot is positive,
    else the first row whose pivot is not."""
    count = pointer.shape[0] - 1
    row = np.zeros(count)  # row k of L D, scattered
    pattern = np.empty(count, dtype=np.int64)
    flag = np.empty(count, dtype=np.int64)
    filled = np.zeros(count, dtype=np.int64)
    for k in range(count):
        top = count
        flag[k] = k
        for p in range(pointer[k], pointer[k + 1]):
            i = index[p]
            if i <= k:
                row[i] += value[p]
                length = 0
                while flag[i] != k:  # the path up the tree, stacked in topological order
                    pattern[length] = i
                    length += 1
                    flag[i] = k
                    i = parent[i]
                while length > 0:
                    top -= 1
                    length -= 1
                    pattern[top] = pattern[length]
        pivot = row[k]
        row[k] = 0.0
        while top < count:
            i = pattern[top]
            top += 1
            entry = row[i]
            row[i] = 0.0
            end = column_pointer[i] + filled[i]
            for p in range(column_pointer[i], end):
                row[row_index[p]] -= lower[p] * entry
            multiplier = entry / diagonal[i]
            pivot -= multiplier * entry
            row_index[end] = k
            lower[end] = multiplier
            filled[i] += 1
        diagonal[k] = pivot
        if not pivot > 0.0:
            return k
    return count


def ldl_factor(matrix: sparse.spmatrix, order: np.ndarray,
               most_entries: float = np.inf) -> tuple | None:
    """(pointer, index, value, diagonal) of P A Pᵀ = L D Lᵀ for the symmetric ``matrix``
    restricted to the rows and columns ``order`` selects, A, P taking its row ``order[k]`` to
    row k (a permutation of them all, or of some: the unknowns of a system with pins): L's
    strictly lower part in CSC (unsigned indices, rows ascending within a column) and D.
    None if A is not positive definite, or if L would have more than ``most_entries``
    entries (known before the numeric work: the order no longer suits the matrix)."""
    permuted = sparse.csc_matrix(matrix)[order][:, order].tocsc()
    permuted.sort_indices()
    count = permuted.shape[0]
    pointer = permuted.indptr.astype(np.int64)
    index = permuted.indices.astype(np.int64)
    parent = np.empty(count, dtype=np.int64)
    column_pointer = _elimination_tree(pointer, index, parent)
    entries = int(column_pointer[-1])
    if entries > most_entries:
        return None
    row_index = np.empty(entries, dtype=np.uint32)
    lower = np.empty(entries)
    diagonal = np.empty(count)
    if _factor_rows(pointer, index, permuted.data, parent, column_pointer, row_index, lower,
                    diagonal) != count:
        return None
    return column_pointer, row_index, lower, diagonal
