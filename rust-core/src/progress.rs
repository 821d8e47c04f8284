//! Progress reporting and cancellation for long work. The callback runs on the calling
//! thread only, between chunks of parallel work, so hosts whose progress APIs are not
//! thread-safe (VTK, Blender, Python under the GIL) can wire it straight through.

use crate::error::{Error, Result};

/// Receives (fraction done in [0, 1], never less than the last one; phase name); returns
/// false to cancel.
pub type Callback<'a> = dyn FnMut(f64, &str) -> bool + 'a;

/// A progress sink with optional callback.
pub struct Progress<'a> {
    callback: Option<&'a mut Callback<'a>>,
    /// Fraction range of the current phase within the window.
    span: (f64, f64),
    /// Fraction range of the whole run that the current operation occupies.
    window: (f64, f64),
    phase: &'static str,
    /// The largest fraction reported so far: a phase whose total is an estimate (the
    /// surface tracked so far) can step back, and a host's bar must not.
    reached: f64,
}

impl<'a> Progress<'a> {
    /// No reporting, never cancelled.
    pub fn none() -> Self {
        Progress {
            callback: None,
            span: (0.0, 1.0),
            window: (0.0, 1.0),
            phase: "",
            reached: 0.0,
        }
    }

    /// Reports to `callback`.
    pub fn new(callback: &'a mut Callback<'a>) -> Self {
        Progress {
            callback: Some(callback),
            span: (0.0, 1.0),
            window: (0.0, 1.0),
            phase: "",
            reached: 0.0,
        }
    }

    /// Maps the next operation's 0..1 onto `from..to` of the whole run, so steps that
    /// each report 0..1 (building a field, then extracting) share one bar.
    pub fn window(&mut self, from: f64, to: f64) {
        self.window = (from, to);
        self.span = (0.0, 1.0);
    }

    /// Starts a phase occupying the fraction range `from..to` of the run.
    pub fn phase(&mut self, name: &'static str, from: f64, to: f64) -> Result<()> {
        self.span = (from, to);
        self.phase = name;
        self.report(0.0)
    }

    /// Runs `work` with the current phase narrowed to its fraction `from..to`, so that a
    /// step reporting 0..1 of its own lands there; the phase is restored afterwards.
    pub fn nested<T>(&mut self, from: f64, to: f64, work: impl FnOnce(&mut Self) -> T) -> T {
        let span = self.span;
        let (a, b) = span;
        self.span = (a + (b - a) * from, a + (b - a) * to);
        let out = work(self);
        self.span = span;
        out
    }

    /// Reports `fraction` of the current phase done; Err(Cancelled) when asked to stop.
    pub fn report(&mut self, fraction: f64) -> Result<()> {
        let (a, b) = self.span;
        let within = a + (b - a) * fraction.clamp(0.0, 1.0);
        let (wa, wb) = self.window;
        let overall = (wa + (wb - wa) * within).max(self.reached);
        self.reached = overall;
        if let Some(cb) = self.callback.as_mut() {
            if !cb(overall, self.phase) {
                return Err(Error::Cancelled);
            }
        }
        Ok(())
    }

    /// Reports the work complete. A cancel answered now is too late and is ignored: the
    /// result exists (a store renamed into place), and a caller told "cancelled" would
    /// believe it does not.
    pub fn done(&mut self) {
        let _ = self.report(1.0);
    }
}

/// Runs `work` over `items` in chunks, reporting after each chunk; the chunks' results are
/// concatenated in order, so the output does not depend on the thread count.
pub fn chunked<T: Sync, R: Send>(
    items: &[T],
    progress: &mut Progress,
    work: impl Fn(&[T]) -> Vec<R> + Sync,
) -> Result<Vec<R>> {
    let mut out = Vec::with_capacity(items.len());
    for_chunks(
        items,
        progress,
        |_, part| work(part),
        |part| out.extend(part),
    )?;
    Ok(out)
}

/// Runs `work` over `items` in chunks (given the index of each chunk's first item) and
/// hands each chunk's result to `sink`, in order, reporting after each chunk: for results
/// that are folded or split as they come, so the whole list of them never exists at once.
pub fn for_chunks<T: Sync, R>(
    items: &[T],
    progress: &mut Progress,
    work: impl Fn(usize, &[T]) -> R + Sync,
    sink: impl FnMut(R),
) -> Result<()> {
    for_ranges(
        items.len(),
        progress,
        |range| work(range.start, &items[range]),
        sink,
    )
}

/// [`for_chunks`] over the indices `0..len`: for passes over a grid's cells that build
/// no list of them first.
pub fn for_ranges<R>(
    len: usize,
    progress: &mut Progress,
    work: impl Fn(std::ops::Range<usize>) -> R + Sync,
    mut sink: impl FnMut(R),
) -> Result<()> {
    // Chunks big enough to keep threads busy, small enough to answer a cancel quickly.
    let chunk = (len / 64).clamp(4096, 1 << 18);
    for start in (0..len).step_by(chunk) {
        let end = (start + chunk).min(len);
        sink(work(start..end));
        progress.report(end as f64 / len as f64)?;
    }
    Ok(())
}

/// [`for_ranges`] concatenating each range's list, in order.
pub fn collect_ranges<R>(
    len: usize,
    progress: &mut Progress,
    work: impl Fn(std::ops::Range<usize>) -> Vec<R> + Sync,
) -> Result<Vec<R>> {
    let mut out = Vec::new();
    for_ranges(len, progress, work, |part| out.extend(part))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A phase whose estimate steps back (tracking's: the surface found so far grows), and
    /// a later phase starting below where an earlier one ended, never move a host's bar
    /// back.
    #[test]
    fn reported_fractions_never_decrease() {
        let mut seen = Vec::new();
        let mut record = |f: f64, _: &str| {
            seen.push(f);
            true
        };
        let mut progress = Progress::new(&mut record);
        progress.phase("tracking", 0.2, 0.6).unwrap();
        for f in [0.5, 0.3, 0.8] {
            progress.report(f).unwrap();
        }
        progress.phase("checking", 0.1, 0.2).unwrap();
        progress.phase("vertices", 0.6, 1.0).unwrap();
        progress.done();
        assert_eq!(seen, [0.2, 0.4, 0.4, 0.52, 0.52, 0.6, 1.0]);
    }
}
