//! The rows of a frame one submission traces: every `stride`-th row from `first`. A slow
//! adapter traces a frame as several such sets, one per UI pass; interleaved rows make each
//! set a even sample of the frame, so what one costs predicts what the next will.

/// Every `stride`-th row of a frame from row `first`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct RowSet {
    pub first: u32,
    pub stride: u32,
}

impl RowSet {
    /// Every row.
    pub const WHOLE: RowSet = RowSet {
        first: 0,
        stride: 1,
    };

    /// How many of a `height`-row frame's rows the set holds.
    pub fn count(&self, height: u32) -> u32 {
        if self.stride == 0 || self.first >= height {
            return 0;
        }
        (height - self.first).div_ceil(self.stride)
    }

    /// The set's two halves: its even and its odd members, each every `2 × stride`-th row.
    pub fn halves(&self) -> [RowSet; 2] {
        let stride = self.stride.saturating_mul(2);
        [
            RowSet {
                first: self.first,
                stride,
            },
            RowSet {
                first: self.first.saturating_add(self.stride),
                stride,
            },
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halves_partition_a_set() {
        let height = 11;
        let rows =
            |s: RowSet| -> Vec<u32> { (s.first..height).step_by(s.stride as usize).collect() };
        let set = RowSet {
            first: 1,
            stride: 3,
        };
        assert_eq!(rows(set), vec![1, 4, 7, 10]);
        assert_eq!(set.count(height), 4);
        let [a, b] = set.halves();
        assert_eq!((rows(a), a.count(height)), (vec![1, 7], 2));
        assert_eq!((rows(b), b.count(height)), (vec![4, 10], 2));
        assert_eq!(RowSet::WHOLE.count(height), height);
        assert_eq!(
            RowSet {
                first: 11,
                stride: 1
            }
            .count(height),
            0
        );
    }
}
