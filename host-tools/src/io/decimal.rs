//! Decimal numbers of text files, parsed from bytes at disk speed
//! ([`parse_f64`]), with exactly the standard library's values.

/// 10^0 … 10^22, all exact in f64.
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20,
    1e21, 1e22,
];

/// The f64 of a field, as `str::parse::<f64>` reads it after `str::trim`,
/// or None where that fails (not a number, or not UTF-8).
///
/// Most values in a DAQ's CSV export are short plain decimals (`-12.345678`,
/// `1.953125e-5`). For those it takes Clinger's fast path
/// (`clinger_fast_path`). Everything else (more digits, larger exponents,
/// `inf`, `nan`, non-ASCII text) goes to `str::parse::<f64>`, so the accepted
/// language and every value are exactly the standard library's (checked
/// against it in this module's tests).
pub fn parse_f64(field: &[u8]) -> Option<f64> {
    match clinger_fast_path(field.trim_ascii()) {
        Some(v) => Some(v),
        None => std::str::from_utf8(field).ok()?.trim().parse().ok(),
    }
}

/// `[+-]? (d+ | d+ '.' d* | d* '.' d+) ([eE] [+-]? d+)?`, exactly rounded,
/// when Clinger's fast path applies; None otherwise (the caller then asks
/// the standard library, which decides).
///
/// The fast path (W. D. Clinger, "How to read floating point numbers
/// accurately", PLDI 1990): with at most 19 digits, a significand w ≤ 2^53
/// and a decimal exponent |e| ≤ 22, both w and 10^|e| are exact f64 values,
/// so the single IEEE multiplication or division w·10^e is the correctly
/// rounded value, the same bits as the standard library's parser.
fn clinger_fast_path(s: &[u8]) -> Option<f64> {
    let (neg, s) = match s.first()? {
        b'-' => (true, &s[1..]),
        b'+' => (false, &s[1..]),
        _ => (false, s),
    };
    let mut w: u64 = 0;
    let mut digits = 0u32;
    let mut i = 0;
    while let Some(d) = s.get(i).and_then(|c| c.checked_sub(b'0')).filter(|d| *d < 10) {
        w = w.wrapping_mul(10).wrapping_add(u64::from(d));
        digits += 1;
        i += 1;
    }
    let mut frac_digits = 0i32;
    if s.get(i) == Some(&b'.') {
        i += 1;
        while let Some(d) = s.get(i).and_then(|c| c.checked_sub(b'0')).filter(|d| *d < 10) {
            w = w.wrapping_mul(10).wrapping_add(u64::from(d));
            digits += 1;
            frac_digits += 1;
            i += 1;
        }
    }
    // 19 digits cannot overflow u64 (10^19 − 1 < 2^64); more take the slow path.
    if digits == 0 || digits > 19 {
        return None;
    }
    let mut exp = 0i32;
    if matches!(s.get(i), Some(b'e' | b'E')) {
        i += 1;
        let neg_exp = match s.get(i) {
            Some(b'-') => {
                i += 1;
                true
            }
            Some(b'+') => {
                i += 1;
                false
            }
            _ => false,
        };
        let start = i;
        while let Some(d) = s.get(i).and_then(|c| c.checked_sub(b'0')).filter(|d| *d < 10) {
            // Beyond 4 digits the exponent is far outside the fast path.
            if i - start >= 4 {
                return None;
            }
            exp = exp * 10 + i32::from(d);
            i += 1;
        }
        if i == start {
            return None;
        }
        if neg_exp {
            exp = -exp;
        }
    }
    if i != s.len() || w > 1 << 53 {
        return None;
    }
    let e = exp - frac_digits;
    let v = w as f64;
    let v = match e {
        0 => v,
        1..=22 => v * POW10[e as usize],
        -22..=-1 => v / POW10[(-e) as usize],
        _ => return None,
    };
    Some(if neg { -v } else { v })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The reference: what the reader did before, field by field.
    fn std_parse(field: &[u8]) -> Option<f64> {
        std::str::from_utf8(field).ok()?.trim().parse().ok()
    }

    fn same(a: Option<f64>, b: Option<f64>) -> bool {
        match (a, b) {
            (Some(x), Some(y)) => x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()),
            (None, None) => true,
            _ => false,
        }
    }

    #[test]
    fn typical_daq_fields_take_the_fast_path_and_equal_std() {
        for f in [
            "0.386455",
            "-13.228708",
            "267.337580",
            "0.000019531",
            "1.953125e-5",
            "-0",
            "+7",
            "5.",
            ".5",
            "1E+05",
            "  42.5 ",
            "9007199254740992",
        ] {
            assert!(clinger_fast_path(f.trim().as_bytes()).is_some(), "{f} missed the fast path");
            assert!(same(parse_f64(f.as_bytes()), std_parse(f.as_bytes())), "{f}");
        }
        // Negative control: these must leave the fast path (and std decides).
        for f in [
            "9007199254740993",
            "1e23",
            "12345678901234567890",
            "inf",
            "NaN",
            "1e",
            ".",
            "-",
            "1.2.3",
            "0x10",
            "1_0",
            "\u{a0}1",
        ] {
            assert!(clinger_fast_path(f.as_bytes()).is_none(), "{f} took the fast path");
            assert!(same(parse_f64(f.as_bytes()), std_parse(f.as_bytes())), "{f}");
        }
        assert_eq!(parse_f64(b"-0").map(f64::to_bits), Some((-0.0f64).to_bits()));
        assert_eq!(parse_f64(b"\xff1"), None);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(4096))]

        /// Any string over the characters numbers are made of: same
        /// acceptance and same bits as the standard library.
        #[test]
        fn agrees_with_std_on_number_like_text(s in "[ +\\-0-9.eE]{0,24}") {
            prop_assert!(same(parse_f64(s.as_bytes()), std_parse(s.as_bytes())), "{:?}", s);
        }

        /// Any f64, written as DAQs and tools write it.
        #[test]
        fn agrees_with_std_on_formatted_values(bits in any::<u64>(), prec in 0usize..12, scale in -30i32..30) {
            let x = f64::from_bits(bits);
            let y = (bits as f64 / u64::MAX as f64 - 0.5) * 10f64.powi(scale);
            for v in [x, y] {
                for f in [format!("{v}"), format!("{v:e}"), format!("{v:.prec$}"), format!("{v:.prec$e}"), format!("{v:E}")] {
                    prop_assert!(same(parse_f64(f.as_bytes()), std_parse(f.as_bytes())), "{}", f);
                }
            }
        }
    }
}
