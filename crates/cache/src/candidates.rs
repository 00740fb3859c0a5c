//! Cluster candidate lists stored narrow (format 4): in Morton order a cluster's candidates
//! lie near its own points, so most clusters store each candidate as a 16-bit offset from
//! the cluster's first point, two to a word; a cluster with a candidate farther away stores
//! full 32-bit indices. `cluster_base` gives each cluster's first word and, in its top bit,
//! which of the two it is; `cluster_start` still counts candidates (the neighbour masks'
//! slots). `candidate` in shaders/step.wgsl reads them the same way.

/// The top bit of a `cluster_base` entry: the cluster stores 32-bit indices.
pub const WIDE_CLUSTER: u32 = 1 << 31;

/// A narrow candidate j of the cluster starting at point `first` is stored as
/// j + NARROW_BIAS − first, which must lie in 0..=u16::MAX.
pub const NARROW_BIAS: u32 = 32768;

/// The narrow offset of candidate `j` in a cluster whose first point is `first`, if it has
/// one.
fn narrow(j: u32, first: u32) -> Option<u16> {
    u16::try_from((i64::from(j) + i64::from(NARROW_BIAS) - i64::from(first)).max(-1)).ok()
}

/// The `cluster_base` entries and packed words of cluster lists (`start`, CSR over `ids`) of
/// clusters of `size` points; `None` if the words would not be addressable by 31 bits.
pub fn pack(start: &[u32], ids: &[u32], size: u32) -> Option<(Vec<u32>, Vec<u32>)> {
    let clusters = start.len().saturating_sub(1);
    let (mut base, mut words) = (Vec::with_capacity(clusters), Vec::new());
    for c in 0..clusters {
        let list = &ids[start[c] as usize..start[c + 1] as usize];
        let first = (c as u32).checked_mul(size)?;
        let at = u32::try_from(words.len())
            .ok()
            .filter(|&a| a < WIDE_CLUSTER)?;
        let offsets: Option<Vec<u16>> = list.iter().map(|&j| narrow(j, first)).collect();
        match offsets {
            Some(offsets) => {
                base.push(at);
                words.extend(offsets.chunks(2).map(|pair| {
                    u32::from(pair[0]) | (u32::from(pair.get(1).copied().unwrap_or(0)) << 16)
                }));
            }
            None => {
                base.push(at | WIDE_CLUSTER);
                words.extend_from_slice(list);
            }
        }
    }
    u32::try_from(words.len()).ok()?;
    Some((base, words))
}

/// Words cluster `c` stores for `count` candidates.
fn words_of(base: u32, count: usize) -> usize {
    if base & WIDE_CLUSTER != 0 {
        count
    } else {
        count.div_ceil(2)
    }
}

/// Checks that each cluster's words follow the previous cluster's, inside `words` words and
/// filling them, so that every candidate slot a cluster counts reads its own words.
pub fn check_layout(start: &[u32], base: &[u32], words: usize) -> Result<(), String> {
    let clusters = start.len().saturating_sub(1);
    if base.len() != clusters {
        return Err(format!(
            "{} cluster bases for {clusters} clusters",
            base.len()
        ));
    }
    let mut next = 0usize;
    for c in 0..clusters {
        let count = start[c + 1].saturating_sub(start[c]) as usize;
        let at = (base[c] & !WIDE_CLUSTER) as usize;
        let need = words_of(base[c], count);
        if at != next || at + need > words {
            return Err(format!(
                "cluster {c}'s candidates (words {at}..{}) do not follow the previous cluster's (which end at word {next}) inside the {words} words",
                at + need
            ));
        }
        next = at + need;
    }
    if next != words {
        return Err(format!(
            "{} words after the last cluster's candidates",
            words - next
        ));
    }
    Ok(())
}

/// The cluster lists back as 32-bit indices (CSR over `start`), or what is wrong: a layout
/// [`check_layout`] refuses, or an index past u32.
pub fn unpack(start: &[u32], base: &[u32], words: &[u32], size: u32) -> Result<Vec<u32>, String> {
    check_layout(start, base, words.len())?;
    let mut out = Vec::with_capacity(start.last().copied().unwrap_or(0) as usize);
    for (c, &b) in base.iter().enumerate() {
        let count = start[c + 1].saturating_sub(start[c]) as usize;
        let at = (b & !WIDE_CLUSTER) as usize;
        if b & WIDE_CLUSTER != 0 {
            out.extend_from_slice(&words[at..at + count]);
            continue;
        }
        let first = u64::from(c as u32) * u64::from(size);
        for k in 0..count {
            let half = (words[at + k / 2] >> (16 * (k % 2))) & 0xffff;
            let j = (first + u64::from(half))
                .checked_sub(u64::from(NARROW_BIAS))
                .and_then(|j| u32::try_from(j).ok())
                .ok_or_else(|| format!("cluster {c}'s candidate {k} lies outside u32"))?;
            out.push(j);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn near_clusters_pack_narrow_far_ones_wide_and_both_come_back() {
        // Three clusters of 32: near candidates, one 40000 points away, and an empty one.
        let start = vec![0, 3, 5, 5];
        let ids = vec![0, 5, 40, 1, 40_032];
        let (base, words) = pack(&start, &ids, 32).unwrap();
        assert_eq!(base, vec![0, 2 | WIDE_CLUSTER, 4]);
        assert_eq!(
            words.len(),
            4,
            "two words for three narrow, two for two wide"
        );
        assert_eq!(unpack(&start, &base, &words, 32).unwrap(), ids);
        // The first cluster's offsets are biased from its first point.
        assert_eq!(words[0] & 0xffff, NARROW_BIAS);
        // A base that skips words, or words past the last cluster, are refused.
        assert!(unpack(&start, &[0, 3 | WIDE_CLUSTER, 5], &words, 32).is_err());
        let mut longer = words.clone();
        longer.push(0);
        assert!(unpack(&start, &base, &longer, 32).is_err());
        // The bias's edges: first − 32768 is narrow, first + 32767 too, one more is wide.
        let start = vec![0, 0, 2];
        let (base, _) = pack(&start, &[0, 32767 + 32], 32).unwrap();
        assert_eq!(base[1] & WIDE_CLUSTER, 0);
        let (base, _) = pack(&start, &[0, 32768 + 32], 32).unwrap();
        assert_ne!(base[1] & WIDE_CLUSTER, 0);
    }
}
