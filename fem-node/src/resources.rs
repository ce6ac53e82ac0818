//! Resource checks made before anything is allocated: the memory a mesh needs against the
//! machine's memory, and readable figures for the messages ("needs ≈ 1.2 TB", "9.9e-5 s").
//!
//! A count from a scene multiplies into allocations (a generated box with
//! `divisions = [1e5, 1e5, 1e5]` is 1e15 elements); without these checks such a scene reaches
//! the allocator and the node aborts with a backtrace instead of naming the field.
//!
//! The machine's memory and the readable figures below are the same as `proto::resources`
//! (which the DEM uses): the engine library `fem` builds without proto
//! (`--no-default-features`, the benches), so it keeps its own copy; change both together.

/// Heap bytes one mesh node costs a model, an order-of-magnitude estimate (not a bound): the
/// static hex8 beam of docs/performance.md peaks at 1.45 GB for 88,641 nodes (16 kB per node:
/// the stiffness matrix with ~81 entries per row and its sparse Cholesky factor, the larger
/// part) and at 190 MB for 12,221 nodes (15.5 kB). Quadratic elements couple more nodes per
/// row, dynamic analyses add the mass matrix and the effective matrix's factor, and the
/// factor's fill grows faster than the node count, so large models need more: a refusal
/// from this estimate is certain, an acceptance is no promise.
pub const BYTES_PER_NODE: u64 = 16_000;

/// Heap bytes one element costs beyond its nodes: connectivity (up to 20 indices of 8 B),
/// offsets, kind, file id and line, strain-gauge and assembly scratch; ~300 B.
pub const BYTES_PER_ELEMENT: u64 = 300;

/// Memory a model of `nodes` nodes and `elements` elements needs (see [`BYTES_PER_NODE`]).
pub fn model_bytes(nodes: u64, elements: u64) -> f64 {
    nodes as f64 * BYTES_PER_NODE as f64 + elements as f64 * BYTES_PER_ELEMENT as f64
}

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
