//! Readable figures and the machine's memory, for the checks every engine makes before it
//! allocates what a scene asks for (a count such as a lattice `count = [1e4, 1e4, 1e4]` or a
//! generated mesh of 1e15 elements must be a scene error naming the field, not an abort in the
//! allocator). The engines add their own per-item estimates (`dem::resources`,
//! `fem::resources`).

/// Memory the system can give this process now, in bytes: `MemAvailable` of /proc/meminfo,
/// else `MemTotal` (kernels before 3.14), else `None` (not Linux, unreadable): then the
/// memory checks are skipped and only overflow is refused.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    meminfo_field(&text, "MemAvailable:").or_else(|| meminfo_field(&text, "MemTotal:"))
}

/// A `/proc/meminfo` field (`"MemAvailable:"`) in bytes (the file gives kB).
fn meminfo_field(text: &str, key: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(key))?;
    let kb: u64 = line[key.len()..].split_whitespace().next()?.parse().ok()?;
    kb.checked_mul(1024)
}

/// Bytes in decimal units with 2–3 significant digits: `1.2 TB`, `512 MB`, `800 B`.
pub fn format_bytes(bytes: f64) -> String {
    const UNITS: [&str; 7] = ["B", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut v = bytes;
    let mut u = 0;
    while v >= 999.5 && u + 1 < UNITS.len() {
        v /= 1000.0;
        u += 1;
    }
    if u == 0 || v >= 9.95 {
        format!("{v:.0} {}", UNITS[u])
    } else {
        format!("{v:.1} {}", UNITS[u])
    }
}

/// A number with at most 4 significant digits, in plain or exponent notation, whichever is
/// usual for its size: `9.9e-5`, `0.00025`, `0.25`, `1.235`, `1.2e7`. For messages: `0.00009900000000000001`
/// tells a user nothing `9.9e-5` does not.
pub fn format_number(v: f64) -> String {
    if !v.is_finite() || v == 0.0 {
        return format!("{v}");
    }
    let a = v.abs();
    if (1e-4..1e5).contains(&a) {
        // 4 significant digits, trailing zeros dropped
        let decimals = (3 - a.log10().floor() as i32).clamp(0, 7) as usize;
        let s = format!("{v:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        let s = format!("{v:.3e}");
        let (mantissa, exponent) = s.split_once('e').unwrap_or((&s, "0"));
        let mantissa = if mantissa.contains('.') {
            mantissa.trim_end_matches('0').trim_end_matches('.')
        } else {
            mantissa
        };
        format!("{mantissa}e{exponent}")
    }
}

/// Refuses `bytes` (what `what` needs) when it exceeds `available` (`None`: unknown, not
/// compared). The message gives both in readable units.
pub fn check_memory(what: &str, bytes: f64, available: Option<u64>) -> Result<(), String> {
    match available {
        Some(avail) if bytes > avail as f64 => Err(format!(
            "{what} needs ≈ {} of memory, more than the {} available on this machine",
            format_bytes(bytes),
            format_bytes(avail as f64)
        )),
        _ => Ok(()),
    }
}

/// Reads a text file after checking that it fits: its text and what is parsed from it take
/// about twice its size (`what` names the file in the message). Errors are messages without
/// the path; the caller names the file.
pub fn read_text_within_memory(path: &std::path::Path, what: &str) -> Result<String, String> {
    let size = std::fs::metadata(path)
        .map_err(|e| format!("cannot read: {e}"))?
        .len();
    check_memory(
        &format!("reading {what} ({})", format_bytes(size as f64)),
        2.0 * size as f64,
        available_memory(),
    )?;
    std::fs::read_to_string(path).map_err(|e| format!("cannot read: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_read_in_decimal_units() {
        assert_eq!(format_bytes(800.0), "800 B");
        assert_eq!(format_bytes(1.2e12), "1.2 TB");
        assert_eq!(format_bytes(5.12e8), "512 MB");
        assert_eq!(format_bytes(5e14), "500 TB");
        assert_eq!(format_bytes(12_345.0), "12 kB");
    }

    #[test]
    fn numbers_print_with_at_most_four_significant_digits() {
        assert_eq!(format_number(0.00009900000000000001), "9.9e-5");
        assert_eq!(format_number(0.25), "0.25");
        assert_eq!(format_number(0.00025000000000000006), "0.00025");
        assert_eq!(format_number(1.23456), "1.235");
        assert_eq!(format_number(1.2e7), "1.2e7");
        assert_eq!(format_number(-2.0), "-2");
        assert_eq!(format_number(0.0), "0");
    }

    #[test]
    fn meminfo_prefers_available_then_total() {
        let t = "MemTotal:       16000000 kB\nMemFree:  100 kB\nMemAvailable:    8000000 kB\n";
        assert_eq!(meminfo_field(t, "MemAvailable:"), Some(8_192_000_000));
        assert_eq!(meminfo_field(t, "MemTotal:"), Some(16_384_000_000));
        assert_eq!(meminfo_field("garbage", "MemTotal:"), None);
        assert!(check_memory("x", 1e12, Some(1_000_000)).is_err());
        assert!(check_memory("x", 1e12, None).is_ok());
    }
}
