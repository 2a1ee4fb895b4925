//! Interpolation on rectilinear grids: locate a coordinate on a monotonic axis, and the
//! validation of axes and arrays that every table loader shares.

use crate::error::{Result, SimError};

/// Index `i` and weight `f` in [0, 1] such that `x ~ axis[i] (1 - f) + axis[i + 1] f`, with `x`
/// clamped to the axis ends (so values beyond the table are held at its edge).
#[inline]
pub fn locate(axis: &[f64], x: f64) -> (usize, f64) {
    let n = axis.len();
    if x <= axis[0] {
        return (0, 0.0);
    }
    if x >= axis[n - 1] {
        return (n - 2, 1.0);
    }
    // Binary search for the cell; axes are short, but this is branch-predictable and O(log n).
    let mut lo = 0;
    let mut hi = n - 1;
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        if axis[mid] <= x {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (lo, (x - axis[lo]) / (axis[lo + 1] - axis[lo]))
}

/// Checks that `axis` has at least two points, all finite and strictly increasing.
pub fn check_axis(table: &str, name: &str, axis: &[f64]) -> Result<()> {
    if axis.len() < 2 {
        return Err(SimError::invalid_table(
            table,
            format!("axis `{name}` has {} points, needs at least 2", axis.len()),
        ));
    }
    if let Some(i) = axis.iter().position(|v| !v.is_finite()) {
        return Err(SimError::invalid_table(
            table,
            format!("axis `{name}`[{i}] = {} is not finite", axis[i]),
        ));
    }
    if let Some(i) = axis.windows(2).position(|w| w[1] <= w[0]) {
        return Err(SimError::invalid_table(
            table,
            format!(
                "axis `{name}` is not strictly increasing at index {}: {} then {}",
                i + 1,
                axis[i],
                axis[i + 1]
            ),
        ));
    }
    Ok(())
}

/// Checks that a flat array has `expected` finite values.
pub fn check_values(
    table: &str,
    name: &str,
    values: &[f64],
    expected: usize,
    shape: &str,
) -> Result<()> {
    if values.len() != expected {
        return Err(SimError::invalid_table(
            table,
            format!(
                "array `{name}` has {} values, expected {expected} (shape {shape})",
                values.len()
            ),
        ));
    }
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(SimError::invalid_table(
            table,
            format!("array `{name}` has a non-finite value at flat index {i}"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locate_clamps_and_interpolates() {
        let axis = [-1.0, 0.0, 2.0, 5.0];
        assert_eq!(locate(&axis, -3.0), (0, 0.0));
        assert_eq!(locate(&axis, 9.0), (2, 1.0));
        assert_eq!(locate(&axis, 1.0), (1, 0.5));
        assert_eq!(locate(&axis, 0.0), (1, 0.0));
        let (i, f) = locate(&axis, 4.25);
        assert_eq!(i, 2);
        assert!((f - 0.75).abs() < 1e-15);
    }

    #[test]
    fn axis_and_value_checks_name_the_problem() {
        assert!(check_axis("t", "x", &[1.0])
            .unwrap_err()
            .to_string()
            .contains("at least 2"));
        assert!(check_axis("t", "x", &[1.0, 1.0])
            .unwrap_err()
            .to_string()
            .contains("index 1"));
        assert!(check_axis("t", "x", &[1.0, f64::NAN])
            .unwrap_err()
            .to_string()
            .contains("not finite"));
        assert!(check_values("t", "cx", &[1.0, 2.0], 3, "(3)")
            .unwrap_err()
            .to_string()
            .contains("expected 3"));
        assert!(check_values("t", "cx", &[1.0, f64::INFINITY], 2, "(2)")
            .unwrap_err()
            .to_string()
            .contains("index 1"));
    }
}
