//! Progress reporting and cancellation for long work. The callback runs on the calling
//! thread only, between chunks of parallel work, so hosts whose progress APIs are not
//! thread-safe (VTK, Blender, Python under the GIL) can wire it straight through.

use crate::error::{Error, Result};

/// Receives (fraction done in [0, 1], phase name); returns false to cancel.
pub type Callback<'a> = dyn FnMut(f64, &str) -> bool + 'a;

/// A progress sink with optional callback.
pub struct Progress<'a> {
    callback: Option<&'a mut Callback<'a>>,
    /// Fraction range of the current phase within the window.
    span: (f64, f64),
    /// Fraction range of the whole run that the current operation occupies.
    window: (f64, f64),
    phase: &'static str,
}

impl<'a> Progress<'a> {
    /// No reporting, never cancelled.
    pub fn none() -> Self {
        Progress {
            callback: None,
            span: (0.0, 1.0),
            window: (0.0, 1.0),
            phase: "",
        }
    }

    /// Reports to `callback`.
    pub fn new(callback: &'a mut Callback<'a>) -> Self {
        Progress {
            callback: Some(callback),
            span: (0.0, 1.0),
            window: (0.0, 1.0),
            phase: "",
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

    /// Reports `fraction` of the current phase done; Err(Cancelled) when asked to stop.
    pub fn report(&mut self, fraction: f64) -> Result<()> {
        let (a, b) = self.span;
        let within = a + (b - a) * fraction.clamp(0.0, 1.0);
        let (wa, wb) = self.window;
        let overall = wa + (wb - wa) * within;
        if let Some(cb) = self.callback.as_mut() {
            if !cb(overall, self.phase) {
                return Err(Error::Cancelled);
            }
        }
        Ok(())
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
    mut sink: impl FnMut(R),
) -> Result<()> {
    // Chunks big enough to keep threads busy, small enough to answer a cancel quickly.
    let chunk = (items.len() / 64).clamp(4096, 1 << 18);
    for (i, part) in items.chunks(chunk).enumerate() {
        sink(work(i * chunk, part));
        progress.report(((i + 1) * chunk).min(items.len()) as f64 / items.len().max(1) as f64)?;
    }
    Ok(())
}
