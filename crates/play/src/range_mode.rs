//! How a field's values span the colour map, as `--field-range` gives it: each step's own
//! range, the series', or a fixed one.

/// Field range on the colour map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RangeMode {
    /// Each step's own range.
    Step,
    /// The series' range: in the player, the manifest's (format 9.1), widened by the steps
    /// shown, or while a bake runs the widest seen over the steps shown so far; in a rendered
    /// sequence, the widest over its steps.
    Series,
    /// From the first value to the second.
    Fixed(f32, f32),
}

impl RangeMode {
    /// `series`, `step` or `LO,HI` (finite, LO below HI); the error says what was expected.
    pub fn parse(text: &str) -> Result<RangeMode, String> {
        match text {
            "series" => return Ok(RangeMode::Series),
            "step" => return Ok(RangeMode::Step),
            _ => {}
        }
        let expected = || format!("{text}: expected series, step or LO,HI (such as -1e5,2.5e5)");
        let (lo, hi) = text.split_once(',').ok_or_else(expected)?;
        let value = |v: &str| v.trim().parse::<f32>().ok().filter(|v| v.is_finite());
        match (value(lo), value(hi)) {
            (Some(lo), Some(hi)) if lo < hi => Ok(RangeMode::Fixed(lo, hi)),
            (Some(_), Some(_)) => Err(format!("{text}: LO must lie below HI")),
            _ => Err(expected()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_parse_or_say_what_was_expected() {
        assert_eq!(RangeMode::parse("series"), Ok(RangeMode::Series));
        assert_eq!(RangeMode::parse("step"), Ok(RangeMode::Step));
        assert_eq!(
            RangeMode::parse("-1e5, 2.5e5"),
            Ok(RangeMode::Fixed(-1e5, 2.5e5))
        );
        for bad in [
            "",
            "steps",
            "1",
            "1,",
            "2,1",
            "1,1",
            "nan,1",
            "0,inf",
            "1e39,2e39",
        ] {
            let why = RangeMode::parse(bad).unwrap_err();
            assert!(why.starts_with(bad), "{bad}: {why}");
        }
    }
}
