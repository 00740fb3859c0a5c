//! The timeline's state: which step is current, whether and how it plays. Pure state, no
//! widgets, no clocks: the frame loop hands [`Timeline::advance`] the seconds that passed, a
//! widget calls the other methods (rerun's `TimeControl`, apart from its time panel).

/// What happens at the end of the played range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Looping {
    /// Stop at the last (or first, backwards) step.
    #[default]
    Off,
    /// Wrap around the whole series.
    All,
    /// Wrap around steps `first..=last`.
    Range { first: usize, last: usize },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Direction {
    #[default]
    Forward,
    Backward,
}

impl Direction {
    pub fn sign(self) -> i64 {
        match self {
            Direction::Forward => 1,
            Direction::Backward => -1,
        }
    }
}

/// The current step of a series of time values, and how playback moves it.
#[derive(Debug, Clone, PartialEq)]
pub struct Timeline {
    times: Vec<f64>,
    current: usize,
    playing: bool,
    direction: Direction,
    looping: Looping,
    /// Steps per second while playing.
    speed: f64,
    /// Fraction of a step played but not yet taken.
    carry: f64,
}

/// The fastest playback speed taken, in steps per second.
pub const MAX_SPEED: f64 = 10_000.0;

impl Timeline {
    /// A paused timeline at step 0 over `times` (one time value per step), playing forward at
    /// 30 steps per second once started.
    pub fn new(times: Vec<f64>) -> Timeline {
        Timeline {
            times,
            current: 0,
            playing: false,
            direction: Direction::Forward,
            looping: Looping::Off,
            speed: 30.0,
            carry: 0.0,
        }
    }

    pub fn len(&self) -> usize {
        self.times.len()
    }

    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    pub fn current(&self) -> usize {
        self.current
    }

    /// The current step's time value (0 for an empty series).
    pub fn time(&self) -> f64 {
        self.times.get(self.current).copied().unwrap_or(0.0)
    }

    pub fn times(&self) -> &[f64] {
        &self.times
    }

    pub fn is_playing(&self) -> bool {
        self.playing
    }

    pub fn direction(&self) -> Direction {
        self.direction
    }

    pub fn looping(&self) -> Looping {
        self.looping
    }

    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// A series that grows while a bake fills its directory: the current step stays.
    pub fn set_times(&mut self, times: Vec<f64>) {
        self.times = times;
        self.current = self.current.min(self.last());
        self.looping = self.clamp_looping(self.looping);
    }

    fn last(&self) -> usize {
        self.times.len().saturating_sub(1)
    }

    /// Jumps to `step` (clamped to the series); playback carries on from there.
    pub fn set_current(&mut self, step: usize) {
        self.current = step.min(self.last());
        self.carry = 0.0;
    }

    /// Moves by `delta` steps, clamped at both ends (a person stepping does not wrap).
    pub fn step_by(&mut self, delta: i64) {
        let target = (self.current as i64).saturating_add(delta).max(0);
        self.set_current(usize::try_from(target).unwrap_or(usize::MAX));
    }

    pub fn home(&mut self) {
        self.set_current(0);
    }

    pub fn end(&mut self) {
        self.set_current(self.last());
    }

    pub fn play(&mut self) {
        // Playing from the end of a range that does not loop starts it over.
        let (first, last) = self.bounds();
        if self.looping == Looping::Off {
            match self.direction {
                Direction::Forward if self.current >= last => self.current = first,
                Direction::Backward if self.current <= first => self.current = last,
                _ => {}
            }
        }
        self.playing = !self.times.is_empty();
        self.carry = 0.0;
    }

    pub fn pause(&mut self) {
        self.playing = false;
        self.carry = 0.0;
    }

    pub fn toggle_play(&mut self) {
        if self.playing {
            self.pause()
        } else {
            self.play()
        }
    }

    pub fn set_direction(&mut self, direction: Direction) {
        self.direction = direction;
    }

    /// Steps per second, clamped to (0, [`MAX_SPEED`]]; a non-finite value is ignored.
    pub fn set_speed(&mut self, steps_per_second: f64) {
        if steps_per_second.is_finite() && steps_per_second > 0.0 {
            self.speed = steps_per_second.min(MAX_SPEED);
        }
    }

    fn clamp_looping(&self, looping: Looping) -> Looping {
        match looping {
            Looping::Range { first, last } => {
                let last = last.min(self.last());
                Looping::Range {
                    first: first.min(last),
                    last,
                }
            }
            other => other,
        }
    }

    /// Sets the looping; a range is clamped to the series and put in order.
    pub fn set_looping(&mut self, looping: Looping) {
        let looping = match looping {
            Looping::Range { first, last } if first > last => Looping::Range {
                first: last,
                last: first,
            },
            other => other,
        };
        self.looping = self.clamp_looping(looping);
    }

    /// The steps playback moves within: the loop range, or the whole series.
    pub fn bounds(&self) -> (usize, usize) {
        match self.looping {
            Looping::Range { first, last } => (first, last),
            _ => (0, self.last()),
        }
    }

    /// Plays `seconds` of time: moves the current step by speed × seconds whole steps (the
    /// fraction carries over). Returns whether the current step changed. At the end of the
    /// range it wraps (loop all or range) or stops and pauses (loop off).
    pub fn advance(&mut self, seconds: f64) -> bool {
        if !self.playing || self.times.is_empty() || !seconds.is_finite() || seconds <= 0.0 {
            return false;
        }
        self.carry += seconds * self.speed;
        let whole = self.carry.floor();
        self.carry -= whole;
        if whole < 1.0 {
            return false;
        }
        let before = self.current;
        let (first, last) = self.bounds();
        let span = (last - first + 1) as i64;
        // Steps taken this call, capped at one lap: a stalled frame loop never spins.
        let moves = (whole as i64).min(span.max(1));
        let at = self.current.clamp(first, last) as i64 - first as i64;
        let target = at + self.direction.sign() * moves;
        let offset = match self.looping {
            Looping::Off => {
                if target < 0 || target >= span {
                    self.playing = false;
                    self.carry = 0.0;
                }
                target.clamp(0, span - 1)
            }
            Looping::All | Looping::Range { .. } => target.rem_euclid(span),
        };
        self.current = first + offset as usize;
        self.current != before
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn timeline(n: usize) -> Timeline {
        Timeline::new((0..n).map(|i| i as f64 * 0.01).collect())
    }

    #[test]
    fn stepping_clamps_at_both_ends() {
        let mut t = timeline(20);
        t.step_by(-1);
        assert_eq!(t.current(), 0);
        t.step_by(10);
        assert_eq!(t.current(), 10);
        t.step_by(10);
        assert_eq!(t.current(), 19);
        t.step_by(1);
        assert_eq!(t.current(), 19);
        t.home();
        assert_eq!(t.current(), 0);
        t.end();
        assert_eq!(t.current(), 19);
        assert!((t.time() - 0.19).abs() < 1e-12);
        t.set_current(1000);
        assert_eq!(t.current(), 19);
    }

    #[test]
    fn playing_moves_by_speed_and_carries_fractions() {
        let mut t = timeline(100);
        t.set_speed(10.0);
        assert!(!t.advance(1.0), "paused timelines stay");
        t.play();
        assert!(!t.advance(0.05), "half a step is not a step");
        assert!(t.advance(0.05));
        assert_eq!(t.current(), 1);
        t.advance(0.5);
        assert_eq!(t.current(), 6);
        t.set_direction(Direction::Backward);
        t.advance(0.3);
        assert_eq!(t.current(), 3);
    }

    #[test]
    fn loop_off_stops_at_the_end_and_play_starts_over() {
        let mut t = timeline(10);
        t.set_speed(100.0);
        t.set_current(8);
        t.play();
        t.advance(1.0);
        assert_eq!(t.current(), 9);
        assert!(!t.is_playing());
        t.play();
        assert_eq!(t.current(), 0, "play at the end restarts");
        t.set_direction(Direction::Backward);
        t.pause();
        t.play();
        assert_eq!(
            t.current(),
            9,
            "play backwards at the start restarts at the end"
        );
    }

    #[test]
    fn loop_all_and_range_wrap() {
        let mut t = timeline(10);
        t.set_looping(Looping::All);
        t.set_speed(1.0);
        t.set_current(8);
        t.play();
        t.advance(3.0);
        assert_eq!(t.current(), 1);
        assert!(t.is_playing());
        t.set_looping(Looping::Range { first: 6, last: 3 });
        assert_eq!(t.looping(), Looping::Range { first: 3, last: 6 });
        t.set_current(6);
        t.advance(1.0);
        assert_eq!(t.current(), 3);
        t.set_direction(Direction::Backward);
        t.advance(1.0);
        assert_eq!(t.current(), 6);
        // A stalled loop moves at most one lap.
        t.advance(1e9);
        assert!((3..=6).contains(&t.current()));
    }

    #[test]
    fn growing_series_keeps_the_step_and_clamps_ranges() {
        let mut t = timeline(3);
        t.end();
        t.set_looping(Looping::Range { first: 1, last: 2 });
        t.set_times((0..50).map(f64::from).collect());
        assert_eq!(t.current(), 2);
        t.set_times(vec![0.0]);
        assert_eq!(t.current(), 0);
        assert_eq!(t.looping(), Looping::Range { first: 0, last: 0 });
        let mut empty = timeline(0);
        empty.play();
        assert!(!empty.is_playing());
        assert!(!empty.advance(1.0));
    }

    #[test]
    fn bad_speeds_are_ignored() {
        let mut t = timeline(5);
        t.set_speed(f64::NAN);
        t.set_speed(-3.0);
        t.set_speed(0.0);
        assert_eq!(t.speed(), 30.0);
        t.set_speed(1e9);
        assert_eq!(t.speed(), MAX_SPEED);
    }
}
