//! Quantities in scene files: a plain number in SI units, or a string with a unit
//! (`"0.1 ms"`, `"50 mm"`, `"210 GPa"`). A unit of the wrong kind is an error naming the
//! expected dimension.

use serde::{Deserialize, Deserializer};

/// Physical dimension of a scene quantity.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dim {
    Time,
    Length,
    Mass,
    Pressure,
    Energy,
}

impl Dim {
    fn si(self) -> &'static str {
        match self {
            Dim::Time => "s",
            Dim::Length => "m",
            Dim::Mass => "kg",
            Dim::Pressure => "Pa",
            Dim::Energy => "J",
        }
    }

    fn name(self) -> &'static str {
        match self {
            Dim::Time => "a time",
            Dim::Length => "a length",
            Dim::Mass => "a mass",
            Dim::Pressure => "a pressure",
            Dim::Energy => "an energy",
        }
    }
}

fn unit_factor(unit: &str) -> Option<(Dim, f64)> {
    Some(match unit {
        "s" => (Dim::Time, 1.0),
        "ms" => (Dim::Time, 1e-3),
        "us" | "µs" => (Dim::Time, 1e-6),
        "ns" => (Dim::Time, 1e-9),
        "min" => (Dim::Time, 60.0),
        "h" => (Dim::Time, 3600.0),
        "m" => (Dim::Length, 1.0),
        "cm" => (Dim::Length, 1e-2),
        "mm" => (Dim::Length, 1e-3),
        "um" | "µm" => (Dim::Length, 1e-6),
        "kg" => (Dim::Mass, 1.0),
        "g" => (Dim::Mass, 1e-3),
        "t" => (Dim::Mass, 1e3),
        "Pa" => (Dim::Pressure, 1.0),
        "kPa" => (Dim::Pressure, 1e3),
        "MPa" => (Dim::Pressure, 1e6),
        "GPa" => (Dim::Pressure, 1e9),
        "J" => (Dim::Energy, 1.0),
        "mJ" => (Dim::Energy, 1e-3),
        "uJ" | "µJ" => (Dim::Energy, 1e-6),
        _ => return None,
    })
}

/// Parses `"<number> <unit>"` (or a bare number string) as a quantity of dimension `dim`, in SI.
pub fn parse_quantity(text: &str, dim: Dim) -> Result<f64, String> {
    let t = text.trim();
    let bytes = t.as_bytes();
    let split = t.char_indices().find(|&(i, c)| {
        let exponent = matches!(c, 'e' | 'E')
            && i > 0
            && (bytes[i - 1].is_ascii_digit() || bytes[i - 1] == b'.')
            && t[i + 1..].starts_with(|n: char| n.is_ascii_digit() || n == '-' || n == '+');
        (c.is_alphabetic() || c == 'µ') && !exponent
    });
    let split = split.map(|(i, _)| i);
    let (num, unit) = match split {
        Some(i) => (t[..i].trim(), t[i..].trim()),
        None => (t, ""),
    };
    let value: f64 = num.parse().map_err(|_| {
        format!(
            "`{text}` is not a number followed by a unit (e.g. \"1.5 {}\")",
            dim.si()
        )
    })?;
    if unit.is_empty() {
        return Ok(value);
    }
    match unit_factor(unit) {
        Some((d, f)) if d == dim => Ok(value * f),
        Some((d, _)) => Err(format!(
            "`{text}`: unit `{unit}` is {}, expected {} (SI unit {})",
            d.name(),
            dim.name(),
            dim.si()
        )),
        None => Err(format!(
            "`{text}`: unknown unit `{unit}` (expected {}, SI unit {})",
            dim.name(),
            dim.si()
        )),
    }
}

macro_rules! quantity {
    ($name:ident, $dim:expr) => {
        /// A quantity in SI units, written as a number or as a string with a unit.
        #[derive(Debug, Clone, Copy, PartialEq, PartialOrd, serde::Serialize)]
        #[serde(transparent)]
        pub struct $name(pub f64);

        impl<'de> Deserialize<'de> for $name {
            fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                #[derive(Deserialize)]
                #[serde(untagged)]
                enum Raw {
                    Num(f64),
                    Int(i64),
                    Text(String),
                }
                let v = match Raw::deserialize(d).map_err(|_| {
                    serde::de::Error::custom(format!(
                        "expected {} (a number in {} or a string like \"1 {}\")",
                        $dim.name(),
                        $dim.si(),
                        $dim.si()
                    ))
                })? {
                    Raw::Num(x) => x,
                    Raw::Int(i) => i as f64,
                    Raw::Text(t) => parse_quantity(&t, $dim).map_err(serde::de::Error::custom)?,
                };
                if !v.is_finite() {
                    return Err(serde::de::Error::custom(format!(
                        "{v} is not a finite {}",
                        $dim.name()
                    )));
                }
                Ok($name(v))
            }
        }
    };
}

/// A duration for people: s, ms, µs or ns with up to 6 significant digits, trailing zeros
/// dropped (1e-4 → "100 µs", 0.00009999999999999999 → "100 µs", 5 → "5 s").
pub fn format_seconds(t: f64) -> String {
    if !t.is_finite() || t == 0.0 {
        return format!("{t} s");
    }
    let (value, unit) = match t.abs() {
        a if a >= 1.0 => (t, "s"),
        a if a >= 1e-3 => (t * 1e3, "ms"),
        a if a >= 1e-6 => (t * 1e6, "µs"),
        _ => (t * 1e9, "ns"),
    };
    let digits = (5 - value.abs().log10().floor() as i32).max(0) as usize;
    let text = format!("{value:.digits$}");
    let text = if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    };
    format!("{text} {unit}")
}

quantity!(Seconds, Dim::Time);
quantity!(Meters, Dim::Length);
quantity!(Joules, Dim::Energy);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantities_parse_with_units_and_exponents() {
        assert_eq!(parse_quantity("0.1 ms", Dim::Time).unwrap(), 1e-4);
        assert_eq!(parse_quantity("1e-4", Dim::Time).unwrap(), 1e-4);
        assert_eq!(parse_quantity("2e-3s", Dim::Time).unwrap(), 2e-3);
        assert!((parse_quantity("50 mm", Dim::Length).unwrap() - 0.05).abs() < 1e-15);
        assert_eq!(parse_quantity("210 GPa", Dim::Pressure).unwrap(), 210e9);
    }

    #[test]
    fn durations_print_in_a_readable_unit() {
        assert_eq!(format_seconds(1e-4), "100 µs");
        assert_eq!(format_seconds(0.00009999999999999999), "100 µs");
        assert_eq!(format_seconds(5.0), "5 s");
        assert_eq!(format_seconds(0.17), "170 ms");
        assert_eq!(format_seconds(2.5e-5), "25 µs");
        assert_eq!(format_seconds(1.234567e-9), "1.23457 ns");
        assert_eq!(format_seconds(1234.5), "1234.5 s");
    }

    #[test]
    fn a_unit_of_the_wrong_kind_is_named() {
        let e = parse_quantity("5 kg", Dim::Time).unwrap_err();
        assert!(e.contains("unit `kg` is a mass, expected a time"), "{e}");
        let e = parse_quantity("5 furlongs", Dim::Length).unwrap_err();
        assert!(e.contains("unknown unit `furlongs`"), "{e}");
    }
}
