//! The C ABI: a thin layer over the Rust API. Opaque handles, core-owned result arrays
//! with explicit free functions, a status code on every fallible call and a thread-local
//! message for the last error. No panic crosses it: every entry runs under
//! `catch_unwind` and a panic becomes `ISOBAR_ERR_INTERNAL`.
//!
//! Threads: a particle handle may be read (extracted from) by several threads at once;
//! freeing it while another thread uses it is the caller's error. Surfaces are immutable.

// These functions are called from C, where every pointer argument is the caller's promise;
// marking them `unsafe fn` would change nothing for C and only hide the checks below.
#![allow(clippy::not_unsafe_ptr_arg_deref)]

mod adaptive;
mod fe;
mod particles;
mod slider;
mod sph;
mod surface;

pub use adaptive::*;
pub use fe::*;
pub use particles::*;
pub use slider::*;
pub use sph::*;
pub use surface::*;

use crate::error::Error;
use std::cell::RefCell;
use std::ffi::{c_char, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

/// Bumped whenever a function's signature or a struct's prefix changes incompatibly.
pub const ISOBAR_ABI_VERSION: u32 = 1;

/// Status of a fallible call.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IsobarStatus {
    Ok = 0,
    /// A null pointer, a bad length, a non-UTF-8 string or a parameter out of range.
    ErrInvalidArgument = 1,
    /// Data that cannot form a field (NaN positions, h <= 0, empty, missing array ...).
    ErrInvalidInput = 2,
    /// A file could not be read or written.
    ErrIo = 3,
    /// A file is not in the format its name says (truncated, corrupt ...).
    ErrFormat = 4,
    /// The work would exceed the memory budget; nothing was allocated.
    ErrOverBudget = 5,
    /// The progress callback asked to stop.
    Cancelled = 6,
    /// A bug in isobar (a caught panic); the message says where.
    ErrInternal = 7,
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
    /// The text `isobar_auto_backend_note` hands out, kept apart from `LAST_ERROR` so the
    /// call's own success (which clears the error message) leaves the note intact.
    static AUTO_NOTE: RefCell<CString> = RefCell::new(CString::default());
    /// What the last call that reports warnings this way warned about although it
    /// succeeded (the slider's builds: what reading the volume lost).
    static LAST_WARNINGS: RefCell<CString> = RefCell::new(CString::default());
}

pub(crate) fn set_last_warnings(warnings: &[String]) {
    let c = warning_lines(warnings);
    LAST_WARNINGS.with(|w| *w.borrow_mut() = c);
}

fn set_last_error(message: &str) {
    let c = CString::new(message.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = c);
}

fn status_of(e: &Error) -> IsobarStatus {
    match e {
        Error::Io { .. } => IsobarStatus::ErrIo,
        Error::Format { .. } => IsobarStatus::ErrFormat,
        Error::MissingArray { .. } | Error::InvalidInput(_) => IsobarStatus::ErrInvalidInput,
        Error::InvalidParameter { .. } => IsobarStatus::ErrInvalidArgument,
        Error::OverBudget { .. } => IsobarStatus::ErrOverBudget,
        Error::Cancelled => IsobarStatus::Cancelled,
    }
}

/// Runs `body`, turning errors and panics into a status and the last-error message.
pub(crate) fn guard(body: impl FnOnce() -> Result<(), Error>) -> IsobarStatus {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => {
            set_last_error("");
            IsobarStatus::Ok
        }
        Ok(Err(e)) => {
            set_last_error(&e.to_string());
            status_of(&e)
        }
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            set_last_error(&format!("internal error in isobar: {what}"));
            IsobarStatus::ErrInternal
        }
    }
}

/// Drops a handle made by `Box::into_raw` in this crate (NULL is ignored), a panic in
/// its destructor caught. The handle is never looked at again, so unwind safety holds
/// whatever it contains.
pub(crate) fn free_boxed<T>(p: *mut T) {
    if !p.is_null() {
        // SAFETY: the caller's promise: made by Box::into_raw here and not freed before.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(p) })));
    }
}

/// An invalid-argument error naming the argument.
pub(crate) fn invalid(name: &'static str, message: impl Into<String>) -> Error {
    Error::InvalidParameter {
        name,
        message: message.into(),
    }
}

/// A required non-null pointer to a whole `T` (a handle). Not for versioned structs: a
/// caller's may be shorter than `T`; `read_versioned` and `versioned_out_size` read those.
pub(crate) fn non_null<'a, T>(p: *const T, name: &'static str) -> Result<&'a T, Error> {
    // SAFETY: the caller promises `p` is null or points to a live T.
    unsafe { p.as_ref() }.ok_or_else(|| invalid(name, "must not be NULL"))
}

/// A UTF-8 C string, or None for NULL.
pub(crate) fn opt_str(p: *const c_char, name: &'static str) -> Result<Option<String>, Error> {
    if p.is_null() {
        return Ok(None);
    }
    // SAFETY: the caller promises a NUL-terminated string.
    let s = unsafe { CStr::from_ptr(p) };
    s.to_str()
        .map(|s| Some(s.to_string()))
        .map_err(|_| invalid(name, "is not valid UTF-8"))
}

/// A slice of `len` items at `p`; NULL is allowed only when `len` is 0.
pub(crate) fn slice<'a, T>(p: *const T, len: usize, name: &'static str) -> Result<&'a [T], Error> {
    if len == 0 {
        return Ok(&[]);
    }
    if p.is_null() {
        return Err(invalid(name, format!("is NULL but its length is {len}")));
    }
    if len
        .checked_mul(std::mem::size_of::<T>())
        .is_none_or(|b| b > isize::MAX as usize)
    {
        return Err(invalid(name, format!("length {len} is too large")));
    }
    // SAFETY: non-null, the caller promises `len` readable items.
    Ok(unsafe { std::slice::from_raw_parts(p, len) })
}

/// The leading `struct_size: u32` of a caller's versioned struct at `p`, read through
/// the raw pointer: no `&T` is formed, since the caller's struct may be an older, shorter
/// version than `T` and a reference would claim all `size_of::<T>()` bytes.
fn struct_size_of<T>(p: *const T, name: &'static str) -> Result<usize, Error> {
    if p.is_null() {
        return Err(invalid(name, "must not be NULL"));
    }
    // SAFETY: non-null; every version of the struct starts with a u32 struct_size (the
    // callers' contract), so these 4 bytes are readable whatever the version.
    Ok(unsafe { p.cast::<u32>().read_unaligned() } as usize)
}

/// A caller's versioned parameter struct laid over our defaults: `T` is `#[repr(C)]` and
/// starts with `struct_size: u32`; the caller's first `struct_size` bytes are taken, fields
/// beyond them keep their defaults, so callers built against an older, shorter struct keep
/// working. `min_size` is the first version's size; `filler` names the defaults function.
/// Only `min(struct_size, size_of::<T>())` bytes of the caller's memory are read.
pub(crate) fn read_versioned<T: Copy + Default>(
    p: *const T,
    name: &'static str,
    min_size: usize,
    filler: &str,
) -> Result<T, Error> {
    let size = struct_size_of(p, name)?;
    let ours = std::mem::size_of::<T>();
    if !(min_size..=ours).contains(&size) {
        return Err(invalid(
            name,
            format!(
                "struct_size is {size}; this library accepts {min_size} to {ours} bytes: fill the struct with {filler}"
            ),
        ));
    }
    let mut out = T::default();
    // SAFETY: the caller's struct holds `struct_size` readable bytes of T's layout (its
    // promise), `out` holds `ours`; the copy takes the smaller. Then struct_size is ours.
    unsafe {
        std::ptr::copy_nonoverlapping(
            p.cast::<u8>(),
            (&mut out as *mut T).cast::<u8>(),
            size.min(ours),
        );
        (&mut out as *mut T).cast::<u32>().write(ours as u32);
    }
    Ok(out)
}

/// Runs `body` with a progress sink that calls the C callback (NULL: no reporting); a
/// non-zero return from the callback cancels.
pub(crate) fn with_progress<R>(
    progress: IsobarProgressFn,
    user: *mut std::ffi::c_void,
    body: impl FnOnce(&mut crate::progress::Progress) -> Result<R, Error>,
) -> Result<R, Error> {
    let mut report = |fraction: f64, phase: &str| match progress {
        Some(f) => {
            let phase = CString::new(phase).unwrap_or_default();
            f(user, fraction, phase.as_ptr()) == 0
        }
        None => true,
    };
    let mut sink = crate::progress::Progress::new(&mut report);
    body(&mut sink)
}

/// NUL-terminated copies of the arrays' names, kept beside a result so C gets stable
/// `const char*` for the handle's lifetime.
pub(crate) fn names_of(arrays: &[crate::field::particles::Attribute]) -> Vec<CString> {
    arrays
        .iter()
        .map(|a| CString::new(a.name.replace('\0', " ")).unwrap_or_default())
        .collect()
}

/// A result's warnings as one NUL-terminated text, one a line, for `*_warnings`.
pub(crate) fn warning_lines(warnings: &[String]) -> CString {
    CString::new(warnings.join("\n").replace('\0', " ")).unwrap_or_default()
}

/// Adds (or replaces) a named array of `count` items × `components` to `arrays`, whose
/// owner holds `items` items (`what`: "particles", "points" in messages). `read` copies the
/// caller's `count × components` values; it runs only after the counts are checked, so a
/// wrong count is refused before the caller's buffer is read.
pub(crate) fn add_array(
    arrays: &mut Vec<crate::field::particles::Attribute>,
    items: usize,
    what: &str,
    name: *const c_char,
    count: usize,
    components: usize,
    read: impl FnOnce(usize) -> Result<Vec<f64>, Error>,
) -> Result<(), Error> {
    let name = opt_str(name, "name")?.ok_or_else(|| invalid("name", "must not be NULL"))?;
    if name.is_empty() {
        return Err(invalid("name", "must not be empty"));
    }
    if components == 0 {
        return Err(invalid("components", "must be at least 1"));
    }
    if count != items {
        return Err(invalid(
            "count",
            format!("array '{name}' has {count} items for {items} {what}"),
        ));
    }
    let len = count
        .checked_mul(components)
        .ok_or_else(|| invalid("count", "too large"))?;
    let data = read(len)?;
    arrays.retain(|a| a.name != name);
    arrays.push(crate::field::particles::Attribute {
        name,
        components,
        data,
    });
    Ok(())
}

/// Writes name, components and data of `arrays[index]` through the out-pointers.
pub(crate) fn attribute_out(
    arrays: &[crate::field::particles::Attribute],
    names: &[CString],
    index: usize,
    name: *mut *const c_char,
    components: *mut usize,
    data: *mut *const f64,
) -> Result<(), Error> {
    let a = arrays.get(index).ok_or_else(|| {
        invalid(
            "index",
            format!("{index} is out of range ({} arrays)", arrays.len()),
        )
    })?;
    put(name, names[index].as_ptr(), "name")?;
    put(components, a.components, "components")?;
    put(data, a.data.as_ptr(), "data")
}

/// The `struct_size` of the caller's statistics struct `out`, checked: a call that will
/// fill one checks it before its work, so a bad struct fails fast. Reads only the leading
/// u32 (no `&T`: the caller's struct may be a shorter, older version).
pub(crate) fn versioned_out_size<T>(out: *mut T, name: &'static str) -> Result<usize, Error> {
    let size = struct_size_of(out as *const T, name)?;
    let ours = std::mem::size_of::<T>();
    if !(4..=ours).contains(&size) {
        return Err(invalid(
            name,
            format!("struct_size is {size}; set it to the struct's sizeof ({ours})"),
        ));
    }
    Ok(size)
}

/// Copies a statistics struct to the caller's `out`, whose leading `struct_size: u32` says
/// how many bytes of the layout it holds (older, shorter structs get the prefix): only
/// bytes 4..min(struct_size, size_of::<T>()) are written, the caller's struct_size is kept.
pub(crate) fn copy_versioned_out<T: Copy>(
    full: T,
    out: *mut T,
    name: &'static str,
) -> Result<(), Error> {
    let size = versioned_out_size(out, name)?.min(std::mem::size_of::<T>());
    // SAFETY: `out` holds at least `size` writable bytes of T's layout (the caller's
    // promise behind struct_size), written through the raw pointer.
    unsafe {
        std::ptr::copy_nonoverlapping(
            (&full as *const T).cast::<u8>().add(4),
            out.cast::<u8>().add(4),
            size - 4,
        )
    };
    Ok(())
}

/// Writes `value` through an out-pointer.
pub(crate) fn put<T>(out: *mut T, value: T, name: &'static str) -> Result<(), Error> {
    if out.is_null() {
        return Err(invalid(name, "output pointer must not be NULL"));
    }
    // SAFETY: non-null, the caller promises it points to writable storage for a T.
    unsafe { out.write(value) };
    Ok(())
}

/// The message of the last failed call on this thread ("" after a success). Valid until
/// the next isobar call on the same thread.
#[no_mangle]
pub extern "C" fn isobar_last_error_message() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}

/// What the last `isobar_slider_build_*` call on this thread warned about although it
/// succeeded, one warning a line ("" for none): values wider than f32 that the store holds
/// coarsely. Results that carry their own warnings (surfaces, samples) have their own
/// `*_warnings` calls. Valid until the next build call on the same thread.
#[no_mangle]
pub extern "C" fn isobar_last_warnings() -> *const c_char {
    LAST_WARNINGS.with(|w| w.borrow().as_ptr())
}

/// Why `ISOBAR_BACKEND_AUTO` runs on the CPU on this machine, for hosts to tell their
/// user: `*note` is set to "" when AUTO would run on the GPU (a hardware adapter), else to
/// the reason the CLI prints after "backend auto: running on the CPU (" (no adapter, a
/// software rasteriser only, or a build without the `gpu` feature). Thread-local storage,
/// valid until the next isobar call on the same thread, as `isobar_last_error_message`.
/// A status rather than a bare string: a panic while probing the adapter comes back as
/// `ISOBAR_ERR_INTERNAL` with its message, never as an "" that would read as "on the GPU".
/// The first call may take a moment (it opens the GPU device once per process).
#[no_mangle]
pub extern "C" fn isobar_auto_backend_note(note: *mut *const c_char) -> IsobarStatus {
    guard(|| {
        let text = crate::gpu::auto_fallback_reason().unwrap_or_default();
        let c = CString::new(text.replace('\0', " ")).unwrap_or_default();
        let ptr = AUTO_NOTE.with(|n| {
            *n.borrow_mut() = c;
            n.borrow().as_ptr()
        });
        put(note, ptr, "note")
    })
}

/// The ABI version (`ISOBAR_ABI_VERSION` of the library actually loaded).
#[no_mangle]
pub extern "C" fn isobar_abi_version() -> u32 {
    ISOBAR_ABI_VERSION
}

/// The library version, e.g. "0.1.0". Static storage.
#[no_mangle]
pub extern "C" fn isobar_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;
    use crate::capi::{IsobarFeParams, IsobarFeStats};

    /// Two pages, the second inaccessible: a struct placed flush against the end of the
    /// first has nothing readable or writable after it, so any access past its
    /// `struct_size` crashes the test instead of passing unnoticed.
    struct Guarded {
        map: memmap2::MmapMut,
        page: usize,
    }

    impl Guarded {
        fn new() -> Guarded {
            // SAFETY: sysconf(_SC_PAGESIZE) has no preconditions.
            let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) } as usize;
            let mut map = memmap2::MmapMut::map_anon(2 * page).unwrap();
            // SAFETY: the second page of our own mapping.
            let rc =
                unsafe { libc::mprotect(map.as_mut_ptr().add(page).cast(), page, libc::PROT_NONE) };
            assert_eq!(rc, 0);
            Guarded { map, page }
        }

        /// `size` bytes of `value` flush against the guard page.
        fn place<T: Copy>(&mut self, value: &T, size: usize) -> *mut T {
            assert!(size <= std::mem::size_of::<T>() && (self.page - size).is_multiple_of(8));
            let at = self.page - size;
            // SAFETY: bytes at..page of the accessible first page.
            unsafe {
                std::ptr::copy_nonoverlapping(
                    (value as *const T).cast::<u8>(),
                    self.map.as_mut_ptr().add(at),
                    size,
                );
                self.map.as_mut_ptr().add(at).cast()
            }
        }
    }

    /// The note is the core's fallback reason ("" where AUTO picks a GPU), survives the
    /// success of its own call, and a NULL out-pointer is refused by name.
    #[test]
    fn auto_backend_note_is_why_auto_skips_the_gpu() {
        let mut note: *const c_char = std::ptr::null();
        assert_eq!(isobar_auto_backend_note(&mut note), IsobarStatus::Ok);
        // SAFETY: set by the call above, valid until the next isobar call here.
        let text = unsafe { CStr::from_ptr(note) }
            .to_str()
            .unwrap()
            .to_string();
        let expected = crate::gpu::auto_fallback_reason().unwrap_or_default();
        assert_eq!(text, expected);
        assert_eq!(
            text.is_empty(),
            crate::gpu::Backend::Auto.resolve().unwrap() == crate::gpu::Backend::Gpu
        );
        assert_eq!(
            isobar_auto_backend_note(std::ptr::null_mut()),
            IsobarStatus::ErrInvalidArgument
        );
        // SAFETY: the thread's last-error message, valid until the next call.
        let message = unsafe { CStr::from_ptr(isobar_last_error_message()) };
        assert!(message.to_str().unwrap().contains("note"), "{message:?}");
    }

    #[test]
    fn shorter_versioned_structs_are_read_and_written_only_to_their_size() {
        let mut guard = Guarded::new();
        let ours = std::mem::size_of::<IsobarFeParams>();
        // A caller built against a (hypothetical) older version whose struct ended before
        // `seed`: 72 bytes, the minimum this read accepts.
        let v1 = 72;
        assert!(v1 < ours);
        let given = IsobarFeParams {
            struct_size: v1 as u32,
            levels: 3,
            iso: 0.25,
            spacing: 0.5,
            split_rounds: 2,
            seed: 99,
            ..IsobarFeParams::default()
        };
        let p = guard.place(&given, v1);
        let read: IsobarFeParams = read_versioned(p, "params", v1, "defaults").unwrap();
        assert_eq!(read.struct_size as usize, ours);
        assert_eq!(
            (read.levels, read.iso, read.spacing, read.split_rounds),
            (3, 0.25, 0.5, 2)
        );
        // Past the caller's struct: the default, not what lay beyond it.
        assert_eq!(read.seed, IsobarFeParams::default().seed);
        // The whole struct is read as before.
        let full = IsobarFeParams { seed: 99, ..given };
        let full = IsobarFeParams {
            struct_size: ours as u32,
            ..full
        };
        let p = guard.place(&full, ours);
        assert_eq!(
            read_versioned(p, "params", v1, "defaults").unwrap().seed,
            99
        );
        // Too short or too long is refused, naming the struct.
        for bad in [8, ours + 8] {
            let p = guard.place(
                &IsobarFeParams {
                    struct_size: bad as u32,
                    ..given
                },
                v1,
            );
            let e = read_versioned(p, "params", v1, "defaults").unwrap_err();
            assert!(
                e.to_string().contains("params") && e.to_string().contains(&bad.to_string()),
                "{e}"
            );
        }

        // An output struct of an older version: only its first 40 bytes (through
        // `evaluations`) exist and are written; its struct_size is kept.
        let short = 40;
        let stats = IsobarFeStats {
            struct_size: short as u32,
            ..IsobarFeStats::default()
        };
        let out = guard.place(&stats, short);
        let full = IsobarFeStats {
            struct_size: 0,
            particles: 1,
            seeds: 2,
            iterations: 3,
            evaluations: 4,
            splits: 5,
            deletes: 6,
            spacing: 7.0,
            max_residual: 8.0,
        };
        copy_versioned_out(full, out, "out").unwrap();
        // SAFETY: the first `short` bytes of the placed struct, read field by field.
        let got = unsafe {
            let out = out.cast_const();
            (
                std::ptr::addr_of!((*out).struct_size).read(),
                std::ptr::addr_of!((*out).particles).read(),
                std::ptr::addr_of!((*out).evaluations).read(),
            )
        };
        assert_eq!(got, (short as u32, 1, 4));
    }
}
