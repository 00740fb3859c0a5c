//! The TIME and FILE sections: time sets (steps, file numbers, times, checked to rise) and
//! file sets (single-file transient chunks), with their numbers inline or in side files.

use std::path::Path;

use super::{Entry, FileSet, FileSetChunk, TimeSet, parse_u32};
use crate::error::{Error, Location, Result, quote};

fn numbers<T: std::str::FromStr>(path: &Path, e: &Entry) -> Result<Vec<T>> {
    e.values
        .iter()
        .map(|v| {
            v.parse::<T>().map_err(|_| {
                Error::parse(
                    path,
                    Location::Line(e.line),
                    format!("numbers after \"{}:\"", e.key),
                    quote(v.as_bytes()),
                )
            })
        })
        .collect()
}

fn single<T: std::str::FromStr>(path: &Path, e: &Entry) -> Result<T> {
    let mut v: Vec<T> = numbers(path, e)?;
    if v.len() != 1 {
        return Err(Error::parse(
            path,
            Location::Line(e.line),
            format!("one number after \"{}:\"", e.key),
            format!("{} values", v.len()),
        ));
    }
    Ok(v.remove(0))
}

/// Reads the whitespace-separated numbers of a `… file:` side file next to the case.
fn numbers_from_file<T: std::str::FromStr>(case: &Path, e: &Entry) -> Result<Vec<T>> {
    let name = e
        .values
        .first()
        .ok_or_else(|| Error::parse(case, Location::Line(e.line), "a file name", "nothing"))?;
    let side = case.parent().unwrap_or(Path::new(".")).join(name);
    let text = std::fs::read_to_string(&side).map_err(|err| Error::io(&side, err))?;
    text.split_whitespace()
        .map(|v| {
            v.parse::<T>()
                .map_err(|_| Error::parse(&side, Location::File, "numbers", quote(v.as_bytes())))
        })
        .collect()
}

pub(super) fn build_time_sets(path: &Path, entries: &[Entry]) -> Result<Vec<TimeSet>> {
    struct Partial {
        id: u32,
        description: Option<String>,
        line: usize,
        steps: Option<usize>,
        start: Option<i64>,
        increment: Option<i64>,
        numbers: Option<Vec<i64>>,
        times: Option<Vec<f64>>,
        /// The line of the "time values" entry.
        times_line: usize,
    }
    impl Partial {
        fn new(id: u32, description: Option<String>, line: usize) -> Partial {
            Partial {
                id,
                description,
                line,
                steps: None,
                start: None,
                increment: None,
                numbers: None,
                times: None,
                times_line: line,
            }
        }
    }
    let mut sets: Vec<Partial> = Vec::new();
    for e in entries {
        if e.key == "time set" {
            let id = e.values.first().and_then(|v| parse_u32(v)).ok_or_else(|| {
                Error::parse(
                    path,
                    Location::Line(e.line),
                    "time set: <number> [description]",
                    quote(e.values.join(" ").as_bytes()),
                )
            })?;
            let description = (e.values.len() > 1).then(|| e.values[1..].join(" "));
            sets.push(Partial::new(id, description, e.line));
            continue;
        }
        if sets.is_empty() {
            // EnSight 6 cases may omit "time set:"; the set is then number 1.
            sets.push(Partial::new(1, None, e.line));
        }
        let set = sets.last_mut().expect("pushed above");
        match e.key.as_str() {
            "number of steps" => set.steps = Some(single(path, e)?),
            "filename start number" => set.start = Some(single(path, e)?),
            "filename increment" => set.increment = Some(single(path, e)?),
            "filename numbers" => set.numbers = Some(numbers(path, e)?),
            "filename numbers file" => set.numbers = Some(numbers_from_file(path, e)?),
            "time values" => {
                set.times = Some(numbers(path, e)?);
                set.times_line = e.line;
            }
            "time values file" => {
                set.times = Some(numbers_from_file(path, e)?);
                set.times_line = e.line;
            }
            _ => {
                return Err(Error::parse(
                    path,
                    Location::Line(e.line),
                    "a TIME keyword (time set, number of steps, filename start number, filename increment, filename numbers, time values)",
                    quote(e.key.as_bytes()),
                ));
            }
        }
    }
    sets.into_iter()
        .map(|p| {
            let at = Location::Line(p.line);
            let steps = p.steps.ok_or_else(|| {
                Error::parse(
                    path,
                    at,
                    format!("\"number of steps:\" in time set {}", p.id),
                    "none",
                )
            })?;
            let times = p.times.ok_or_else(|| {
                Error::parse(
                    path,
                    at,
                    format!("\"time values:\" in time set {}", p.id),
                    "none",
                )
            })?;
            if times.len() != steps {
                return Err(Error::parse(
                    path,
                    at,
                    format!("{steps} time values in time set {}", p.id),
                    format!("{}", times.len()),
                ));
            }
            // Steps are ordered by time: every value finite, each after the one before.
            let expected = format!("finite, increasing time values in time set {}", p.id);
            for (i, t) in times.iter().enumerate() {
                let problem = if !t.is_finite() {
                    Some(format!("time value {i} is {t}"))
                } else if i > 0 && *t <= times[i - 1] {
                    Some(format!(
                        "time value {i} ({t}) after {} ({})",
                        times[i - 1],
                        if *t == times[i - 1] {
                            "a duplicate"
                        } else {
                            "decreasing"
                        }
                    ))
                } else {
                    None
                };
                if let Some(found) = problem {
                    return Err(Error::parse(
                        path,
                        Location::Line(p.times_line),
                        expected,
                        found,
                    ));
                }
            }
            let file_numbers = match (p.numbers, p.start) {
                (Some(n), _) => {
                    if n.len() != steps {
                        return Err(Error::parse(
                            path,
                            at,
                            format!("{steps} filename numbers in time set {}", p.id),
                            format!("{}", n.len()),
                        ));
                    }
                    n
                }
                (None, Some(start)) => {
                    let inc = p.increment.unwrap_or(1);
                    // Numbers past i64 are an error, not a wrap-around.
                    (0..steps as i64)
                        .map(|i| i.checked_mul(inc).and_then(|d| start.checked_add(d)))
                        .collect::<Option<Vec<i64>>>()
                        .ok_or_else(|| {
                            Error::parse(
                                path,
                                at,
                                format!("file numbers that fit in 64 bits for time set {}", p.id),
                                format!("start {start}, increment {inc} over {steps} steps"),
                            )
                        })?
                }
                (None, None) => Vec::new(),
            };
            Ok(TimeSet {
                id: p.id,
                description: p.description,
                times,
                file_numbers,
            })
        })
        .collect()
}

pub(super) fn build_file_sets(path: &Path, entries: &[Entry]) -> Result<Vec<FileSet>> {
    let mut sets: Vec<FileSet> = Vec::new();
    let mut pending_index: Option<i64> = None;
    for e in entries {
        match e.key.as_str() {
            "file set" => {
                sets.push(FileSet {
                    id: single(path, e)?,
                    chunks: Vec::new(),
                });
                pending_index = None;
            }
            "filename index" => pending_index = Some(single(path, e)?),
            "number of steps" => {
                let set = sets.last_mut().ok_or_else(|| {
                    Error::parse(
                        path,
                        Location::Line(e.line),
                        "\"file set:\" first",
                        quote(e.key.as_bytes()),
                    )
                })?;
                set.chunks.push(FileSetChunk {
                    index: pending_index.take(),
                    steps: single(path, e)?,
                });
            }
            _ => {
                return Err(Error::parse(
                    path,
                    Location::Line(e.line),
                    "a FILE keyword (file set, filename index, number of steps)",
                    quote(e.key.as_bytes()),
                ));
            }
        }
    }
    Ok(sets)
}
