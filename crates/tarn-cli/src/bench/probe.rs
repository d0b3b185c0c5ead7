//! Measuring this process: medians of timings, peak memory, CPU time and page faults.

/// Median of a non-empty sample (the mean of the middle two for an even count).
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// Peak resident set of this process (VmHWM from /proc/self/status), bytes.
pub fn peak_memory_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// CPU seconds this process has used so far, user and system, every thread (getrusage);
/// `None` off unix.
pub fn cpu_seconds() -> Option<f64> {
    #[cfg(unix)]
    {
        // SAFETY: getrusage writes one `rusage` into the zeroed struct it is given.
        unsafe {
            let mut u: libc::rusage = std::mem::zeroed();
            if libc::getrusage(libc::RUSAGE_SELF, &mut u) == 0 {
                let t = |v: libc::timeval| v.tv_sec as f64 + v.tv_usec as f64 * 1e-6;
                return Some(t(u.ru_utime) + t(u.ru_stime));
            }
        }
        None
    }
    #[cfg(not(unix))]
    {
        None
    }
}

/// Minor page faults of this process so far (getrusage `ru_minflt`); `None` off unix.
pub fn minor_faults() -> Option<u64> {
    #[cfg(unix)]
    {
        // SAFETY: getrusage writes one `rusage` into the zeroed struct it is given.
        unsafe {
            let mut u: libc::rusage = std::mem::zeroed();
            if libc::getrusage(libc::RUSAGE_SELF, &mut u) == 0 {
                return Some(u.ru_minflt as u64);
            }
        }
        None
    }
    #[cfg(not(unix))]
    {
        None
    }
}
