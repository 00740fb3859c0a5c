//! Every point's neighbour list as one CSR index over pieces: the lists of consecutive points
//! kept in one buffer per piece. The lists stage writes each block of points into its own
//! buffer, and those buffers become the lists as they are; a single contiguous array would
//! mean allocating, faulting in and copying half a gigabyte again at 1M points.

/// Neighbour lists: `start[i]..start[i + 1]` is point i's list, in offsets over all pieces
/// together; piece p holds the lists of points `p · piece_points ..`, its first id at offset
/// `start[p · piece_points]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Neighbours {
    start: Vec<u32>,
    piece_points: usize,
    pieces: Vec<Vec<u32>>,
}

impl Neighbours {
    /// Lists from a CSR index and its ids, in one piece; `None` if `start` is not a CSR index
    /// over `ids` (empty, not from 0, not monotone, or not ending at `ids.len()`).
    pub fn from_csr(start: Vec<u32>, ids: Vec<u32>) -> Option<Neighbours> {
        let points = start.len().checked_sub(1)?;
        Self::from_pieces(start, points.max(1), vec![ids])
    }

    /// Lists from a CSR index and the ids of each `piece_points` consecutive points; `None`
    /// if the pieces do not hold exactly what `start` says.
    pub(crate) fn from_pieces(
        start: Vec<u32>,
        piece_points: usize,
        pieces: Vec<Vec<u32>>,
    ) -> Option<Neighbours> {
        let points = start.len().checked_sub(1)?;
        let monotone = start.first() == Some(&0) && start.windows(2).all(|w| w[0] <= w[1]);
        let fits = piece_points > 0
            && pieces.len() == points.div_ceil(piece_points).max(1)
            && pieces.iter().enumerate().all(|(p, ids)| {
                let first = (p * piece_points).min(points);
                let last = ((p + 1) * piece_points).min(points);
                (start[last] - start[first]) as usize == ids.len()
            });
        (monotone && fits).then_some(Neighbours {
            start,
            piece_points,
            pieces,
        })
    }

    /// How many points have a list.
    pub fn len(&self) -> usize {
        self.start.len() - 1
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// How many ids all lists hold together.
    pub fn total(&self) -> usize {
        *self.start.last().unwrap_or(&0) as usize
    }

    /// The CSR index: point i's list is `start()[i]..start()[i + 1]` over all lists in order.
    pub fn start(&self) -> &[u32] {
        &self.start
    }

    /// Point i's list.
    pub fn of(&self, i: usize) -> &[u32] {
        let p = i / self.piece_points;
        let base = self.start[p * self.piece_points];
        &self.pieces[p][(self.start[i] - base) as usize..(self.start[i + 1] - base) as usize]
    }

    /// Every id of every list, in point order.
    pub fn ids(&self) -> impl Iterator<Item = u32> + '_ {
        self.pieces.iter().flatten().copied()
    }
}

/// The ids of a CSR index (offsets `start`, ids `ids`) split into the lists of each
/// `per_piece` consecutive points, with those points, to be worked on in parallel.
pub fn csr_pieces<'a>(
    start: &[u32],
    ids: &'a mut [u32],
    per_piece: usize,
) -> Vec<(std::ops::Range<usize>, &'a mut [u32])> {
    let n = start.len().saturating_sub(1);
    let per_piece = per_piece.max(1);
    let mut pieces = Vec::with_capacity(n.div_ceil(per_piece));
    let mut rest = ids;
    for first in (0..n).step_by(per_piece) {
        let last = (first + per_piece).min(n);
        let (piece, tail) = rest.split_at_mut((start[last] - start[first]) as usize);
        pieces.push((first..last, piece));
        rest = tail;
    }
    pieces
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pieces_give_the_lists_of_one_csr() {
        // Five points' lists, of lengths 2, 0, 3, 1, 2; pieces of two points.
        let start = vec![0, 2, 2, 5, 6, 8];
        let ids: Vec<u32> = (10..18).collect();
        let pieces = vec![vec![10, 11], vec![12, 13, 14, 15], vec![16, 17]];
        let csr = Neighbours::from_csr(start.clone(), ids.clone()).unwrap();
        let split = Neighbours::from_pieces(start.clone(), 2, pieces.clone()).unwrap();
        for i in 0..5 {
            let want = &ids[start[i] as usize..start[i + 1] as usize];
            assert_eq!(csr.of(i), want, "point {i}");
            assert_eq!(split.of(i), want, "point {i}");
        }
        assert_eq!(split.ids().collect::<Vec<_>>(), ids);
        assert_eq!((split.len(), split.total()), (5, 8));
        // Pieces that do not hold what the index says, and indices that are not CSR.
        assert!(Neighbours::from_pieces(start.clone(), 2, pieces[..2].to_vec()).is_none());
        assert!(Neighbours::from_pieces(start.clone(), 3, pieces).is_none());
        assert!(Neighbours::from_csr(vec![0, 3, 2], vec![1, 2]).is_none());
        assert!(Neighbours::from_csr(vec![0, 2], vec![1, 2, 3]).is_none());
        assert!(Neighbours::from_csr(vec![], vec![]).is_none());
        assert!(Neighbours::from_csr(vec![0], vec![]).is_some_and(|n| n.is_empty()));
    }
}
