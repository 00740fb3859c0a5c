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

/// Peak device memory of a GPU bake per point of the step, measured: a 4M-point sphere step
/// peaked at 2332 MiB on the H200 (`nvidia-smi`, the driver's context included), some
/// 610 bytes per point; with headroom, over a base for the context and the passes.
const DEVICE_BYTES_PER_POINT: u64 = 768;
const DEVICE_BASE_BYTES: u64 = 256 << 20;

/// Steps baked at once by default, each on its share of the cores (`BatchOptions::threads`),
/// at least one:
/// - on the CPU, half the cores: a step is parallel inside, but not all of it, and its
///   reading and writing are serial (on the 16-core H200 host a series of eight 1M-point
///   steps took 13.4 s with 2 jobs, 11.3 s with 4 and 10.4 s with 8);
/// - where the stages run on a device (`device_memory`, its bytes), three for every two
///   cores: each step waits for the device part of its time (its passes queue behind the
///   other steps'), and other steps' host work fills the wait (64 steps of 1M on an H100
///   host, alternated: 7.49 steps/s on average with 16 jobs, 7.93 with 20, 8.34 with 24, 7.83
///   with 28, 7.67 with 32; on the H200 host 4.95 with 4, 5.48-5.92 with 8, 6.27 with 16); and
///   no more than half the device's memory holds, the rest left to the driver and to a player
///   on the same device;
///
/// and no more than three quarters of the memory available hold.
pub fn default_jobs(
    cores: usize,
    available: Option<u64>,
    points: Option<usize>,
    device_memory: Option<u64>,
) -> (usize, String) {
    let by_cores = match device_memory {
        Some(_) => (cores * 3 / 2).max(1),
        None => (cores / 2).max(1),
    };
    let per_job = points.map(|p| BAKE_BASE_BYTES + p as u64 * BAKE_BYTES_PER_POINT);
    let by_memory = match (available, per_job) {
        (Some(a), Some(j)) => ((a / 4 * 3) / j).max(1) as usize,
        _ => usize::MAX,
    };
    let per_device_job = points.map(|p| DEVICE_BASE_BYTES + p as u64 * DEVICE_BYTES_PER_POINT);
    let by_device = match (device_memory, per_device_job) {
        (Some(d), Some(j)) => ((d / 2) / j).max(1) as usize,
        _ => usize::MAX,
    };
    let jobs = by_cores.min(by_memory).min(by_device);
    let gb = |bytes: u64| bytes as f64 / 1e9;
    let mut why = format!(
        "{cores} cores{}",
        if device_memory.is_some() {
            ", three steps for every two cores on the device"
        } else {
            ""
        }
    );
    if let (Some(a), Some(j), Some(p)) = (available, per_job, points) {
        why += &format!(
            "; a step of {p} points needs about {:.2} GB, {:.1} GB available",
            gb(j),
            gb(a)
        );
    }
    if let (Some(d), Some(j)) = (device_memory, per_device_job) {
        why += &format!("; about {:.2} GB of the device's {:.1} GB", gb(j), gb(d));
    }
    // "Up to": the batch takes no more jobs than it has steps.
    let steps = if jobs == 1 { "step" } else { "steps" };
    (
        jobs,
        format!("baking up to {jobs} {steps} at once ({why}; --jobs sets it)"),
    )
}

/// Job `job`'s share of `threads` split among `jobs` (the first ones take the remainder;
/// at least one each): the threads of its own rayon pool, in a batch and for a viewer's steps
/// ahead alike.
pub(crate) fn thread_share(threads: usize, jobs: usize, job: usize) -> usize {
    let jobs = jobs.max(1);
    (threads / jobs + usize::from(job < threads % jobs)).max(1)
}

/// Steps a viewer bakes ahead at once (a raw case played: each of its loaders bakes one), of
/// the `batch_jobs` that `slosh bake` would take: no more than half the cores, so that each
/// step has two threads or more. A bake a viewer waits for shares the machine with the steps
/// ahead, and a step ahead on one thread takes seconds: 64 steps of 1M points played on an
/// H100 host (`slosh bench scrub --raw-case --raw-case-gpu`, one call) at 5.30 steps/s with
/// 24 at once (jumps p50 772 ms, p99 1356 ms, playback latency p99 2766 ms, 23.0 GB at
/// peak), 4.73 with 12, 5.92 with 8 (566, 912 and 1482 ms, 9.4 GB), where 6 loaders over a
/// window of 4 steps played at 4.39 (534, 836, 2260 ms).
pub fn viewer_jobs(batch_jobs: usize, cores: usize) -> usize {
    batch_jobs.clamp(1, (cores / 2).max(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jobs_default_to_half_the_cores_within_memory() {
        assert_eq!(default_jobs(2, Some(24 << 30), Some(100_000), None).0, 1);
        assert_eq!(
            default_jobs(16, Some(128 << 30), Some(1_000_000), None).0,
            8
        );
        assert_eq!(default_jobs(64, None, None, None).0, 32);
        // 12 GiB available, a 1M-point step needs about 2.1 GB: four at a time.
        assert_eq!(default_jobs(16, Some(12 << 30), Some(1_000_000), None).0, 4);
        // 4 GiB available, a 1M-point step needs about 2.1 GB: one at a time.
        let (jobs, why) = default_jobs(64, Some(4 << 30), Some(1_000_000), None);
        assert_eq!(jobs, 1, "{why}");
        assert!(why.contains("1000000 points"), "{why}");
    }

    #[test]
    fn device_jobs_take_three_for_two_cores_within_half_the_device() {
        // The H200 host: 16 cores, 141 GB on the device; 1M points need about 1 GB there.
        let (jobs, why) = default_jobs(16, Some(128 << 30), Some(1_000_000), Some(141 << 30));
        assert_eq!(jobs, 24, "{why}");
        assert!(why.contains("of the device's"), "{why}");
        // One core: one job.
        assert_eq!(default_jobs(1, None, None, Some(8 << 30)).0, 1);
        // An 8 GiB card: half of it holds four steps of 1M points (about 1.04 GB each).
        assert_eq!(
            default_jobs(16, Some(64 << 30), Some(1_000_000), Some(8 << 30)).0,
            4
        );
        // and one of 4M points (3.33 GB); at least one whatever the step.
        assert_eq!(
            default_jobs(16, Some(64 << 30), Some(4_000_000), Some(8 << 30)).0,
            1
        );
        assert_eq!(
            default_jobs(16, Some(64 << 30), Some(40_000_000), Some(8 << 30)).0,
            1
        );
        // Host memory still bounds them: 12 GiB available hold four 1M-point steps.
        assert_eq!(
            default_jobs(16, Some(12 << 30), Some(1_000_000), Some(141 << 30)).0,
            4
        );
    }
}
