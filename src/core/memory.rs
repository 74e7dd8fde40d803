//! What this machine's memory can still hold: the bound a command checks before building
//! something large, so it refuses in one line where it would abort allocating.

/// The memory this machine can still give a process (Linux's `MemAvailable`), in bytes; `None`
/// where it does not say.
pub fn available_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}
