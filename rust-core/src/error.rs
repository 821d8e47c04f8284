//! The one error type every fallible core call returns. Each variant names what is wrong
//! (file, field, index) so a host can show it to the user as it is.

use std::path::{Path, PathBuf};

/// Result alias used throughout the crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong in the core, worded for the person who supplied the input.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An operating-system error while reading or writing a file.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file whose contents do not follow its format (truncated, corrupt, unsupported).
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    /// A named array the caller asked for is not in the data.
    #[error("no array named '{name}' in the particle data (available: {available})")]
    MissingArray { name: String, available: String },
    /// Input data that cannot describe a valid field (NaN coordinates, h <= 0, empty set ...).
    #[error("{0}")]
    InvalidInput(String),
    /// A parameter outside its meaningful range.
    #[error("parameter '{name}': {message}")]
    InvalidParameter { name: &'static str, message: String },
    /// The work would need more memory than the budget allows; refused before allocating.
    #[error(
        "{what} would need {}, over the memory budget of {budget_bytes} bytes",
        needed_text(*.needed_bytes)
    )]
    OverBudget {
        what: String,
        needed_bytes: u64,
        budget_bytes: u64,
    },
    /// The progress callback asked to stop.
    #[error("cancelled")]
    Cancelled,
}

impl Error {
    /// Shorthand for a format error about `path`.
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Error::Format {
            path: path.into(),
            message: message.into(),
        }
    }

    /// This error as one about the data read from the file `path`, for checks that run
    /// after reading and know no file ("particle 17 has a non-finite position", a missing
    /// array): the message then names the file too. Other errors are returned as they are.
    pub fn in_file(self, path: &Path) -> Self {
        match self {
            Error::InvalidInput(m) => Error::InvalidInput(format!("{}: {m}", path.display())),
            Error::MissingArray { .. } => {
                Error::InvalidInput(format!("{}: {self}", path.display()))
            }
            other => other,
        }
    }

    /// This error from work that ran on `budget` less the `held` bytes `holder` keeps, as
    /// an error against the whole `budget`: an over-budget refusal then counts `held` in
    /// what was needed and names what holds it. Other errors are returned as they are.
    pub fn besides(self, held: u64, holder: &str, budget: u64) -> Self {
        match self {
            Error::OverBudget {
                what, needed_bytes, ..
            } if held > 0 => Error::OverBudget {
                what: format!("{what}, besides the {held} bytes of {holder},"),
                needed_bytes: needed_bytes.saturating_add(held),
                budget_bytes: budget,
            },
            other => other,
        }
    }

    /// Shorthand for an I/O error about `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}

/// A byte count as the budget error says it: a count that saturated (a grid of more cells
/// than 64 bits count, from a tiny h or one stray particle far away) is not a number of
/// bytes anyone can act on.
fn needed_text(bytes: u64) -> String {
    if bytes == u64::MAX {
        "more bytes than a 64-bit count holds".into()
    } else {
        format!("{bytes} bytes")
    }
}

/// `x` (positive, finite) to three significant digits in plain notation, rounded up (the
/// "at least" of a remedy such as "a grid factor of at least 0.0352 fits" must hold): a
/// factor such as 0.000412 must not print as 0.000.
pub(crate) fn three_digits(x: f64) -> String {
    if !(x > 0.0 && x.is_finite()) {
        return format!("{x}");
    }
    let decimals = (2 - x.log10().floor() as i64).max(0) as usize;
    let scale = 10f64.powi(decimals as i32);
    // Less a hair, so that a value already on three digits (0.0349 is 349.00000000000006
    // hundred-thousandths) is not raised by its representation error.
    let up = (x * scale * (1.0 - 1e-12)).ceil() / scale;
    format!("{up:.decimals$}")
}

#[cfg(test)]
mod tests {
    use super::{three_digits, Error};

    #[test]
    fn factors_keep_three_significant_digits() {
        assert_eq!(three_digits(0.0349), "0.0349");
        assert_eq!(three_digits(0.000412), "0.000412");
        assert_eq!(three_digits(0.5), "0.500");
        assert_eq!(three_digits(12.34), "12.4");
        assert_eq!(three_digits(0.10004), "0.101");
        assert_eq!(three_digits(0.0), "0");
        assert_eq!(three_digits(f64::INFINITY), "inf");
        assert_eq!(three_digits(1234.0), "1234");
    }

    #[test]
    fn a_saturated_byte_count_is_not_printed_as_a_number() {
        let over = |needed_bytes| Error::OverBudget {
            what: "the grid".into(),
            needed_bytes,
            budget_bytes: 4096,
        };
        assert_eq!(
            over(u64::MAX).to_string(),
            "the grid would need more bytes than a 64-bit count holds, over the memory budget \
             of 4096 bytes"
        );
        assert_eq!(
            over(8192).to_string(),
            "the grid would need 8192 bytes, over the memory budget of 4096 bytes"
        );
    }
}
