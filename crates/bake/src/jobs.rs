//! How many steps a machine bakes at once: its cores, the memory available now, and what a
//! step of a given size needs.

/// Logical cores this process may use.
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Bytes of memory available now (`MemAvailable` in /proc/meminfo), where known.
pub fn available_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Peak memory of a bake per point of the step, measured: sphere steps of 100k, 400k and 1M
/// points peaked at 177 MB, 679 MB and 1.55 GB resident (`/usr/bin/time -v slosh bake …
/// --jobs 1`), about 1.52 KB per point over a base of 25 MB; with headroom.
const BAKE_BYTES_PER_POINT: u64 = 2048;
const BAKE_BASE_BYTES: u64 = 64 << 20;

/// Steps baked at once by default, each on its share of the cores (`BatchOptions::threads`):
/// half the cores (a step is parallel inside, but not all of it, and its reading and writing
/// are serial: on the 16-core H200 host a series of eight 1M-point steps took 13.4 s with 2
/// jobs, 11.3 s with 4 and 10.4 s with 8), no more than three quarters of the memory
/// available hold, at least one.
pub fn default_jobs(
    cores: usize,
    available: Option<u64>,
    points: Option<usize>,
) -> (usize, String) {
    let by_cores = (cores / 2).max(1);
    let per_job = points.map(|p| BAKE_BASE_BYTES + p as u64 * BAKE_BYTES_PER_POINT);
    let by_memory = match (available, per_job) {
        (Some(a), Some(j)) => ((a / 4 * 3) / j).max(1) as usize,
        _ => usize::MAX,
    };
    let jobs = by_cores.min(by_memory);
    let memory = match (available, per_job, points) {
        (Some(a), Some(j), Some(p)) => format!(
            "; a step of {p} points needs about {:.2} GB, {:.1} GB available",
            j as f64 / 1e9,
            a as f64 / 1e9
        ),
        _ => String::new(),
    };
    (
        jobs,
        format!("baking {jobs} steps at once ({cores} cores{memory}; --jobs sets it)"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jobs_default_to_half_the_cores_within_memory() {
        assert_eq!(default_jobs(2, Some(24 << 30), Some(100_000)).0, 1);
        assert_eq!(default_jobs(16, Some(128 << 30), Some(1_000_000)).0, 8);
        assert_eq!(default_jobs(64, None, None).0, 32);
        // 12 GiB available, a 1M-point step needs about 2.1 GB: four at a time.
        assert_eq!(default_jobs(16, Some(12 << 30), Some(1_000_000)).0, 4);
        // 4 GiB available, a 1M-point step needs about 2.1 GB: one at a time.
        let (jobs, why) = default_jobs(64, Some(4 << 30), Some(1_000_000));
        assert_eq!(jobs, 1, "{why}");
        assert!(why.contains("1000000 points"), "{why}");
    }
}
