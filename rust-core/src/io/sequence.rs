//! Numbered frame sequences: `frame_####.vtk`, `frame_{}.vtk`, `frame_%04d.vtk`, or one
//! existing frame whose siblings are wanted.

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// How the frame number may be written.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Digits {
    /// Zero-padded to this width; numbers that outgrow the width are written in full
    /// (`####` matches `0042` and `12345`, not `42` or `00042`).
    Padded(usize),
    /// Any run of digits.
    Any,
}

impl Digits {
    fn accepts(self, digits: &str) -> bool {
        if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
            return false;
        }
        match self {
            Digits::Any => true,
            Digits::Padded(w) => {
                digits.len() == w || (digits.len() > w && !digits.starts_with('0'))
            }
        }
    }
}

/// Expands a frame pattern into the existing files it names, sorted by frame number.
///
/// Accepted forms: a run of `#` (that many digits, zero-padded, or more digits once the
/// number outgrows the padding), `{}` or `%d` (any digits), `%0Nd` (like N `#`), or the path
/// of one existing file: if its name ends in digits before the extension (`frame_0001.vtk`),
/// every sibling with the same prefix, extension and padding; otherwise just that file.
/// Errors when nothing matches, naming the pattern.
pub fn expand_sequence(pattern: &str) -> Result<Vec<PathBuf>> {
    let path = Path::new(pattern);
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => Some(p.to_path_buf()),
        _ => None,
    };
    let file_name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| Error::InvalidInput(format!("'{pattern}' names no file")))?;

    let (prefix, digits, suffix) = if path.is_file() {
        let (stem, ext) = split_extension(&file_name);
        let run = trailing_digits(stem);
        if run.is_empty() {
            return Ok(vec![path.to_path_buf()]);
        }
        let prefix = &stem[..stem.len() - run.len()];
        (
            prefix.to_string(),
            Digits::Padded(run.len()),
            ext.to_string(),
        )
    } else {
        let parsed = placeholder(&file_name).ok_or_else(|| {
            let why = if dir
                .as_deref()
                .is_some_and(|d| placeholder(&d.to_string_lossy()).is_some())
            {
                "the frame-number placeholder must be in the file name, not the folder"
            } else {
                "no such file, and no frame-number placeholder (####, {}, %d or %04d) in it"
            };
            Error::InvalidInput(format!("frame pattern '{pattern}': {why}"))
        })?;
        parsed
    };

    let listing_dir = dir.clone().unwrap_or_else(|| PathBuf::from("."));
    let entries = std::fs::read_dir(&listing_dir).map_err(|e| Error::io(&listing_dir, e))?;
    let mut frames: Vec<(u64, String)> = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| Error::io(&listing_dir, e))?;
        let Ok(name) = entry.file_name().into_string() else {
            continue;
        };
        let Some(middle) = name
            .strip_prefix(prefix.as_str())
            .and_then(|rest| rest.strip_suffix(suffix.as_str()))
        else {
            continue;
        };
        if !digits.accepts(middle) || entry.path().is_dir() {
            continue;
        }
        // More digits than u64 holds cannot be a frame counter; skip rather than misorder.
        if let Ok(number) = middle.parse::<u64>() {
            frames.push((number, name));
        }
    }
    if frames.is_empty() {
        return Err(Error::InvalidInput(format!(
            "frame pattern '{pattern}': no file in {} matches",
            listing_dir.display()
        )));
    }
    frames.sort();
    Ok(frames
        .into_iter()
        .map(|(_, name)| match &dir {
            Some(d) => d.join(name),
            None => PathBuf::from(name),
        })
        .collect())
}

/// The frames a command reads for `input`, writing each to `output` (and its statistics to
/// `stats`): an existing file with an output that has no '#' is that file alone (one file
/// in, one mesh out, whatever its numbered siblings); otherwise the frames of the sequence
/// `input` names (a pattern, or one file of a numbered set), whose outputs must then be
/// patterns with '#' when there is more than one frame, or each would overwrite the last.
pub fn frames_for(input: &str, output: &Path, stats: Option<&Path>) -> Result<Vec<PathBuf>> {
    let has_frame = |p: &Path| p.to_string_lossy().contains('#');
    if Path::new(input).is_file() && !has_frame(output) {
        return Ok(vec![PathBuf::from(input)]);
    }
    let frames = expand_sequence(input)?;
    warn_if_gaps(input, &frames);
    if frames.len() > 1 {
        for (name, path) in [("output", Some(output)), ("stats-json", stats)] {
            if path.is_some_and(|p| !has_frame(p)) {
                return Err(Error::InvalidParameter {
                    name,
                    message: format!(
                        "{} frames match '{input}'; give a pattern with '#' for the frame \
                         number (e.g. surface_####.ply, stats_####.json)",
                        frames.len()
                    ),
                });
            }
        }
    }
    Ok(frames)
}

/// The frame number of a file: the digits that end its name before the extension
/// (`frame_0042.vtk` and `frame_0042.bgeo.gz` give 42; `particles.vtk` gives `None`).
pub fn frame_number(path: &Path) -> Option<u64> {
    let name = path.file_name()?.to_string_lossy();
    let (stem, _) = split_extension(&name);
    trailing_digits(stem).parse().ok()
}

/// An output path for frame `frame`: the first run of `#` in `pattern` replaced by the
/// frame number, zero-padded to the run's width (a pattern without `#` is used as is).
pub fn fill_frame(pattern: &str, frame: u64) -> String {
    let Some(start) = pattern.find('#') else {
        return pattern.to_string();
    };
    let width = pattern[start..].chars().take_while(|&c| c == '#').count();
    format!(
        "{}{:0width$}{}",
        &pattern[..start],
        frame,
        &pattern[start + width..]
    )
}

/// The output path of the input file `frame` for the output `pattern`: [`fill_frame`]
/// with the frame's number (0 when its name ends in no digits), also for a sequence of
/// one frame; a pattern without `#` is returned as it is.
pub fn frame_output(pattern: &Path, frame: &Path) -> PathBuf {
    let text = pattern.to_string_lossy();
    if !text.contains('#') {
        return pattern.to_path_buf();
    }
    PathBuf::from(fill_frame(&text, frame_number(frame).unwrap_or(0)))
}

/// Checks, before any frame is read, that every frame's output and statistics file
/// (`stats`, if asked for) can be written: `check` tests an output path for its kind of
/// file. A bad path is then found now, not after the first extraction.
pub fn check_frame_outputs(
    frames: &[PathBuf],
    output: &Path,
    stats: Option<&Path>,
    check: fn(&Path) -> Result<()>,
) -> Result<()> {
    for frame in frames {
        check(&frame_output(output, frame))?;
        if let Some(stats) = stats {
            super::check_output(&frame_output(stats, frame))?;
        }
    }
    Ok(())
}

/// Says on stderr (also with `--quiet`) what the extraction of `frame` warned about: an
/// isovalue with no surface, a kernel wider than the particles (the extraction's
/// `warnings`, which every host shows its own way).
pub fn print_warnings(frame: &Path, warnings: &[String]) {
    for w in warnings {
        eprintln!("isobar: warning: {}: {w}", frame.display());
    }
}

/// Missing frames listed at most.
const SHOWN: usize = 10;

/// The frame numbers a sequence skips: with every step between its frames a multiple of
/// the smallest (1, or 10 for a solver that saves every tenth step), the numbers of that
/// stride that have no file. An irregular sequence has no gaps to name. Returns how many
/// are missing and the first [`SHOWN`] of them: counted, not listed, so that a stray
/// `frame_20240101` beside frames 0 and 1 costs nothing.
pub fn missing_frames(frames: &[PathBuf]) -> (u64, Vec<u64>) {
    let numbers: Vec<u64> = frames.iter().filter_map(|f| frame_number(f)).collect();
    let Some(step) = numbers
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|&d| d > 0)
        .min()
    else {
        return (0, Vec::new());
    };
    if numbers.windows(2).any(|w| (w[1] - w[0]) % step != 0) {
        return (0, Vec::new());
    }
    let count = numbers
        .windows(2)
        .map(|w| ((w[1] - w[0]) / step).saturating_sub(1))
        .sum();
    let first = numbers
        .windows(2)
        .flat_map(|w| (1..(w[1] - w[0]) / step).map(move |k| w[0] + k * step))
        .take(SHOWN)
        .collect();
    (count, first)
}

/// Says on stderr which frames of the sequence `pattern` are missing, so a hole left by a
/// failed solver step is not passed over in silence; the present frames still run.
pub fn warn_if_gaps(pattern: &str, frames: &[PathBuf]) {
    let (count, first) = missing_frames(frames);
    if count == 0 {
        return;
    }
    let mut list: Vec<String> = first.iter().map(u64::to_string).collect();
    if count > first.len() as u64 {
        list.push(format!("... ({count} in all)"));
    }
    eprintln!(
        "isobar: warning: '{pattern}': frame{} {} missing; going on with the {} present",
        if count == 1 { "" } else { "s" },
        list.join(", "),
        frames.len()
    );
}

/// Splits `name` into stem and extension, treating `.x.gz` as one extension.
fn split_extension(name: &str) -> (&str, &str) {
    let Some(dot) = name.rfind('.').filter(|&i| i > 0) else {
        return (name, "");
    };
    let (stem, ext) = name.split_at(dot);
    if ext.eq_ignore_ascii_case(".gz") {
        if let Some(inner) = stem.rfind('.').filter(|&i| i > 0) {
            return name.split_at(inner);
        }
    }
    (stem, ext)
}

fn trailing_digits(s: &str) -> &str {
    let start = s
        .char_indices()
        .rev()
        .take_while(|(_, c)| c.is_ascii_digit())
        .last()
        .map_or(s.len(), |(i, _)| i);
    &s[start..]
}

/// Finds the frame-number placeholder in a file name: (prefix, digits, suffix).
fn placeholder(name: &str) -> Option<(String, Digits, String)> {
    if let Some(start) = name.find('#') {
        let width = name[start..].chars().take_while(|&c| c == '#').count();
        return Some((
            name[..start].to_string(),
            Digits::Padded(width),
            name[start + width..].to_string(),
        ));
    }
    if let Some(start) = name.find("{}") {
        return Some((
            name[..start].to_string(),
            Digits::Any,
            name[start + 2..].to_string(),
        ));
    }
    // printf style: %d, %4d, %04d
    let mut search = 0;
    while let Some(i) = name[search..].find('%').map(|i| i + search) {
        let spec: String = name[i + 1..]
            .chars()
            .take_while(|c| c.is_ascii_digit())
            .collect();
        if name[i + 1 + spec.len()..].starts_with('d') {
            let digits = match spec.strip_prefix('0').map(str::parse::<usize>) {
                Some(Ok(w)) if w > 0 => Digits::Padded(w),
                _ => Digits::Any,
            };
            return Some((
                name[..i].to_string(),
                digits,
                name[i + 2 + spec.len()..].to_string(),
            ));
        }
        search = i + 1;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::super::test_support::scratch_dir;
    use super::*;

    fn names(paths: &[PathBuf]) -> Vec<String> {
        paths
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect()
    }

    #[test]
    fn patterns_and_sibling_expansion() {
        let dir = scratch_dir("sequence");
        for n in [
            "frame_0010.vtk",
            "frame_0002.vtk",
            "frame_0001.vtk",
            "frame_12345.vtk",
            "frame_01.vtk",
            "frame_00010.vtk",
            "frame_0003.vtu",
            "other_0001.vtk",
            "frame_0004.bgeo.gz",
        ] {
            std::fs::write(dir.join(n), b"").unwrap();
        }
        std::fs::create_dir(dir.join("frame_0005.vtk")).unwrap();
        let d = dir.display();
        let expand = |p: String| names(&expand_sequence(&p).unwrap());
        let padded = [
            "frame_0001.vtk",
            "frame_0002.vtk",
            "frame_0010.vtk",
            "frame_12345.vtk",
        ];
        assert_eq!(expand(format!("{d}/frame_####.vtk")), padded);
        assert_eq!(expand(format!("{d}/frame_%04d.vtk")), padded);
        assert_eq!(expand(format!("{d}/frame_0002.vtk")), padded);
        assert_eq!(
            expand(format!("{d}/frame_{{}}.vtk")),
            [
                "frame_0001.vtk",
                "frame_01.vtk",
                "frame_0002.vtk",
                "frame_00010.vtk",
                "frame_0010.vtk",
                "frame_12345.vtk"
            ]
        );
        assert_eq!(expand(format!("{d}/frame_%d.vtk")).len(), 6);
        assert_eq!(
            expand(format!("{d}/frame_0004.bgeo.gz")),
            ["frame_0004.bgeo.gz"]
        );
        let full = expand_sequence(&format!("{d}/frame_####.vtk")).unwrap();
        assert_eq!(full[0], dir.join("frame_0001.vtk"));

        let e = expand_sequence(&format!("{d}/nothing_####.vtk"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("nothing_####.vtk") && e.contains("no file"),
            "{e}"
        );
        let e = expand_sequence(&format!("{d}/missing.vtk"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("missing.vtk") && e.contains("no such file"),
            "{e}"
        );
        let e = expand_sequence("/nonexistent-isobar/f_##.vtk").unwrap_err();
        assert!(matches!(e, Error::Io { .. }), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn single_files_without_a_number_are_their_own_sequence() {
        let p = super::super::test_support::shared_data_dir().join("cube_2366_particles.vtk");
        let s = expand_sequence(p.to_str().unwrap()).unwrap();
        assert_eq!(s, vec![p]);
    }

    #[test]
    fn output_patterns_take_the_frame_number() {
        assert_eq!(fill_frame("surf/f_####.ply", 7), "surf/f_0007.ply");
        assert_eq!(fill_frame("f_##.vtp", 1234), "f_1234.vtp");
        assert_eq!(fill_frame("plain.ply", 3), "plain.ply");
    }

    #[test]
    fn gaps_are_found_at_the_sequence_stride() {
        let frames = |numbers: &[u64]| -> Vec<PathBuf> {
            numbers
                .iter()
                .map(|n| PathBuf::from(format!("d/f_{n:04}.vtk")))
                .collect()
        };
        assert_eq!(missing_frames(&frames(&[1, 2, 3, 4])), (0, vec![]));
        assert_eq!(missing_frames(&frames(&[1, 2, 4, 7])), (3, vec![3, 5, 6]));
        assert_eq!(missing_frames(&frames(&[0, 10, 20, 50])), (2, vec![30, 40]));
        // A stray far frame: counted, the first ten listed.
        let (count, first) = missing_frames(&frames(&[0, 1, 20240101]));
        assert_eq!((count, first.len(), first[9]), (20240099, 10, 11));
        // Irregular steps (0, 10, 25) have no stride to measure gaps by.
        assert_eq!(missing_frames(&frames(&[0, 10, 25])), (0, vec![]));
        assert_eq!(missing_frames(&frames(&[5])), (0, vec![]));
    }

    #[test]
    fn frame_numbers() {
        assert_eq!(frame_number(Path::new("a/frame_0042.vtk")), Some(42));
        assert_eq!(frame_number(Path::new("frame_7.bgeo.gz")), Some(7));
        assert_eq!(frame_number(Path::new("12")), Some(12));
        assert_eq!(frame_number(Path::new("particles.vtk")), None);
        assert_eq!(
            frame_number(Path::new("f_99999999999999999999999.vtk")),
            None
        );
    }
}
