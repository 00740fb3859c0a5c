//! Wall-clock laps of pipeline stages (the surface build, the bake).

use std::time::Instant;

/// A lap named "stage: part" is a part of the stage's lap before it (its time is within it),
/// for reports that break a stage down: (stage, part), or `None` for a stage's own lap.
pub fn stage_part(name: &str) -> Option<(&str, &str)> {
    name.split_once(": ")
}

#[derive(Debug)]
pub struct StageClock {
    last: Instant,
    pub laps: Vec<(&'static str, f64)>,
}

impl StageClock {
    pub fn start() -> StageClock {
        StageClock {
            last: Instant::now(),
            laps: Vec::new(),
        }
    }

    /// Records the time since the previous lap (or the start) under `name`.
    pub fn lap(&mut self, name: &'static str) {
        let now = Instant::now();
        self.laps.push((name, (now - self.last).as_secs_f64()));
        self.last = now;
    }

    /// Appends laps timed elsewhere and restarts the clock from now.
    pub fn extend(&mut self, laps: &[(&'static str, f64)]) {
        self.laps.extend_from_slice(laps);
        self.last = Instant::now();
    }
}
