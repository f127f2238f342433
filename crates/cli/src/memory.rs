//! The process's peak resident memory, as the kernel counts it (what a user's `time -v` or
//! task manager shows), for `fogray fit`'s report.

/// Peak resident bytes of this process so far; `None` where the system does not say.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub fn peak_resident_bytes() -> Option<u64> {
    let mut usage = std::mem::MaybeUninit::<libc::rusage>::zeroed();
    // SAFETY: getrusage writes one rusage into the pointer it is given, which points at one.
    let done = unsafe { libc::getrusage(libc::RUSAGE_SELF, usage.as_mut_ptr()) } == 0;
    // SAFETY: initialised by the call above (and zeroed before it).
    let usage = unsafe { usage.assume_init() };
    // Linux counts ru_maxrss in kibibytes.
    (done && usage.ru_maxrss > 0).then(|| usage.ru_maxrss as u64 * 1024)
}

/// Peak resident bytes of this process so far; `None` where the system does not say.
#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn peak_resident_bytes() -> Option<u64> {
    None
}
