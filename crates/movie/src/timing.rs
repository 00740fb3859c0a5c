//! How long each frame of a movie of a series is shown: a fixed rate, or the series' own
//! times (real time, or slowed down by a factor).

/// Where a movie's frame durations come from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Timing {
    /// Frames a second.
    Fps(f64),
    /// The steps' simulated times, each interval stretched by this factor (1: real time; 10:
    /// ten times slower than the simulation ran).
    SeriesTimes { slowdown: f64 },
}

/// Seconds each of the frames of steps at `times` is shown under `timing`. From times, frame
/// i lasts until step i + 1's time, and the last frame as long as the one before it; the
/// times must increase (else the answer says which steps do not, and to give a rate).
pub fn frame_seconds(timing: Timing, times: &[f64]) -> Result<Vec<f64>, String> {
    match timing {
        Timing::Fps(fps) => {
            if !(fps.is_finite() && fps > 0.0) {
                return Err(format!("{fps} frames a second: expected a positive rate"));
            }
            Ok(vec![1.0 / fps; times.len()])
        }
        Timing::SeriesTimes { slowdown } => {
            if !(slowdown.is_finite() && slowdown > 0.0) {
                return Err(format!(
                    "a slow-motion factor of {slowdown}: expected a positive number"
                ));
            }
            if times.len() < 2 {
                return Err(
                    "one step has no interval to time a movie by: give a frame rate (--fps)".into(),
                );
            }
            let mut seconds: Vec<f64> = Vec::with_capacity(times.len());
            for (i, pair) in times.windows(2).enumerate() {
                let dt = (pair[1] - pair[0]) * slowdown;
                if !(dt.is_finite() && dt > 0.0) {
                    return Err(format!(
                        "steps {} and {} of the movie have times {} and {}: the series' times do not advance, so they cannot time it; give a frame rate (--fps)",
                        i,
                        i + 1,
                        pair[0],
                        pair[1]
                    ));
                }
                seconds.push(dt);
            }
            seconds.push(seconds[seconds.len() - 1]);
            Ok(seconds)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_and_times_give_each_frame_its_duration() {
        assert_eq!(
            frame_seconds(Timing::Fps(25.0), &[0.0; 3]).unwrap(),
            vec![0.04; 3]
        );
        let times = [0.0, 0.01, 0.03, 0.06];
        let real = frame_seconds(Timing::SeriesTimes { slowdown: 1.0 }, &times).unwrap();
        let slow = frame_seconds(Timing::SeriesTimes { slowdown: 10.0 }, &times).unwrap();
        for (got, want) in real.iter().zip([0.01, 0.02, 0.03, 0.03]) {
            assert!((got - want).abs() < 1e-12, "{real:?}");
        }
        for (s, r) in slow.iter().zip(&real) {
            assert!((s - 10.0 * r).abs() < 1e-12);
        }
        let stuck =
            frame_seconds(Timing::SeriesTimes { slowdown: 1.0 }, &[0.0, 0.1, 0.1]).unwrap_err();
        assert!(
            stuck.contains("steps 1 and 2") && stuck.contains("--fps"),
            "{stuck}"
        );
        let single = frame_seconds(Timing::SeriesTimes { slowdown: 1.0 }, &[0.5]).unwrap_err();
        assert!(single.contains("--fps"), "{single}");
    }
}
