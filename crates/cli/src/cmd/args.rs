//! Value parsers shared by the subcommands' options: numbers that must be finite (clap's
//! `f32` parser accepts `nan` and `inf`, which would silently give a black or NaN image).

/// A finite `f32` (`--exposure -1.5`); `nan` and `inf` are refused.
pub fn finite_f32(s: &str) -> Result<f32, String> {
    let v: f32 = s.trim().parse().map_err(|_| format!("'{s}' is not a number"))?;
    if !v.is_finite() {
        return Err(format!("'{s}' is not a finite number"));
    }
    Ok(v)
}

/// A finite `f32` above 0 (an epsilon, a scale).
#[allow(dead_code)] // for denoise's --eps-normal, --eps-depth, --scene-scale, --albedo-eps
pub fn positive_f32(s: &str) -> Result<f32, String> {
    let v = finite_f32(s)?;
    if v <= 0.0 {
        return Err(format!("{s} must be greater than 0"));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_and_non_positive_values_are_refused() {
        assert_eq!(finite_f32("-1.5"), Ok(-1.5));
        assert_eq!(finite_f32(" 2 "), Ok(2.0));
        for bad in ["nan", "NaN", "inf", "-inf", "infinity", "1e39", "abc", ""] {
            assert!(finite_f32(bad).is_err(), "{bad}");
        }
        assert_eq!(positive_f32("0.01"), Ok(0.01));
        for bad in ["0", "-0.0", "-1", "nan"] {
            assert!(positive_f32(bad).is_err(), "{bad}");
        }
    }
}
