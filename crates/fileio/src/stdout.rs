//! Writing results to stdout without panicking when the reader goes away (`slosh info | head`).

use std::io::{ErrorKind, Write};

pub fn print(text: &str) -> std::io::Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() == ErrorKind::BrokenPipe => Ok(()),
        other => other,
    }
}

/// The first error other than a closed pipe met while writing to stdout, reported by `main`
/// once the command has done its work (a full disk behind `>` must not stop a bake halfway,
/// nor pass unnoticed).
static STDOUT_ERROR: std::sync::Mutex<Option<String>> = std::sync::Mutex::new(None);

/// Writes `text` to stdout, never panicking: a reader that went away (`| head`) is fine, any
/// other failure is remembered for [`stdout_error`].
pub fn say_text(text: &str) {
    if let Err(e) = print(text) {
        let mut first = STDOUT_ERROR
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        first.get_or_insert_with(|| e.to_string());
    }
}

/// Why stdout could not be written, if it could not.
pub fn stdout_error() -> Option<String> {
    STDOUT_ERROR
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .clone()
}

/// `println!` that never panics on a closed or full stdout (see [`say_text`]).
#[macro_export]
macro_rules! say {
    ($($arg:tt)*) => {
        $crate::stdout::say_text(&format!("{}\n", format_args!($($arg)*)))
    };
}
