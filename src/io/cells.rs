//! Cells of the measurement CSV ↔ SI numbers, exactly.
//!
//! Conversion to SI: degrees with `f64::to_radians`; millimetres by moving
//! the decimal point (the cell `12.5` in mm is read as the decimal `12.5e-3`
//! m), so the conversion is correctly rounded and a written file reads back
//! bit for bit. The writer prints the shortest text that reads back to the
//! same `f64` (Rust's `{}`), in the file's units; it is bit-exact for rad, m
//! and mm, and for deg whenever some decimal degree value maps back exactly
//! under `to_radians` (else within 1 ulp).

use crate::io::error::ErrorKind;
use crate::io::units::{AngleUnit, LengthUnit};

/// The unit of a cell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Scale {
    One,
    Angle(AngleUnit),
    Length(LengthUnit),
}

pub(crate) fn parse_int(cell: &str) -> Result<i64, String> {
    cell.parse()
        .map_err(|_| format!("'{cell}' is not an integer"))
}

/// A finite real in SI; see the module doc for the unit conversion.
pub(crate) fn parse_real(cell: &str, scale: Scale) -> Result<f64, (ErrorKind, String)> {
    parse_real_written(cell, scale).map(|(_, v)| v)
}

/// [`parse_real`] with the number as written, before the unit's
/// conversion (read once: a second parse of the cell for it was a tenth of
/// reading a large file).
pub(crate) fn parse_real_written(
    cell: &str,
    scale: Scale,
) -> Result<(f64, f64), (ErrorKind, String)> {
    let v: f64 = cell
        .parse()
        .map_err(|_| (ErrorKind::Syntax, format!("'{cell}' is not a number")))?;
    if !v.is_finite() {
        return Err((ErrorKind::NonFinite, format!("non-finite value '{cell}'")));
    }
    Ok((
        v,
        match scale {
            Scale::One | Scale::Angle(AngleUnit::Rad) | Scale::Length(LengthUnit::M) => v,
            Scale::Angle(AngleUnit::Deg) => v.to_radians(),
            Scale::Length(LengthUnit::Mm) => milli(cell).unwrap_or(v / 1000.0),
        },
    ))
}

/// The decimal `cell · 10⁻³`, correctly rounded.
fn milli(cell: &str) -> Option<f64> {
    let text = match cell.find(['e', 'E']) {
        Some(i) => {
            let exp: i32 = cell[i + 1..].parse().ok()?;
            format!("{}e{}", &cell[..i], exp.checked_sub(3)?)
        }
        None => format!("{cell}e-3"),
    };
    text.parse().ok()
}

/// `s` (Rust `{}` of a finite f64: no exponent) times 1000, as decimal text.
fn times_1000(s: &str) -> String {
    let (sign, digits) = s.strip_prefix('-').map_or(("", s), |d| ("-", d));
    let (int, frac) = digits.split_once('.').unwrap_or((digits, ""));
    let frac = format!("{frac:0<3}");
    let int = format!("{int}{}", &frac[..3]);
    let int = match int.trim_start_matches('0') {
        "" => "0",
        t => t,
    };
    match frac[3..].trim_end_matches('0') {
        "" => format!("{sign}{int}"),
        f => format!("{sign}{int}.{f}"),
    }
}

/// The next `f64` after `w` toward +∞ (`up`) or −∞.
fn next_after(w: f64, up: bool) -> f64 {
    if w == 0.0 {
        let tiny = f64::from_bits(1);
        return if up { tiny } else { -tiny };
    }
    let bits = w.to_bits();
    if (w > 0.0) == up {
        f64::from_bits(bits + 1)
    } else {
        f64::from_bits(bits - 1)
    }
}

/// Text of a value in `scale` that [`parse_real`] reads back as `v` (SI).
pub(crate) fn format_real(v: f64, scale: Scale) -> String {
    match scale {
        Scale::One | Scale::Angle(AngleUnit::Rad) | Scale::Length(LengthUnit::M) => format!("{v}"),
        Scale::Length(LengthUnit::Mm) => times_1000(&format!("{v}")),
        Scale::Angle(AngleUnit::Deg) => {
            let w0 = v.to_degrees();
            let (u1, d1) = (next_after(w0, true), next_after(w0, false));
            let candidates = [w0, u1, d1, next_after(u1, true), next_after(d1, false)];
            let w = candidates
                .into_iter()
                .find(|w| w.is_finite() && w.to_radians().to_bits() == v.to_bits())
                .unwrap_or(w0);
            format!("{w}")
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::io::cells::*;

    #[test]
    fn times_1000_moves_the_point() {
        for (s, t) in [
            ("0", "0"),
            ("-0", "-0"),
            ("1", "1000"),
            ("0.0123", "12.3"),
            ("-1.5", "-1500"),
            ("0.0000001", "0.0001"),
            ("123.456789", "123456.789"),
        ] {
            assert_eq!(times_1000(s), t);
        }
    }

    #[test]
    fn milli_is_correctly_rounded() {
        assert_eq!(milli("12.5"), Some(0.0125));
        assert_eq!(milli("1.5E+3"), Some(1.5));
        assert_eq!(milli("-7e-1"), Some(-0.0007));
        assert_eq!(milli("1e-2147483648"), None);
    }
}
