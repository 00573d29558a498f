//! Numbers read back as the document's contract says: finite where the mount
//! is, `null` (NaN) allowed elsewhere.

use super::*;

/// A number that must be finite: `null` (how JSON writes NaN) and anything
/// else are refused in words.
pub(super) fn finite<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
    match serde_json::Value::deserialize(deserializer)? {
        serde_json::Value::Null => Err(serde::de::Error::custom(
            "is null, not a finite number (JSON writes NaN and infinities as null)",
        )),
        value => value
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| serde::de::Error::custom(format!("is {value}, not a finite number"))),
    }
}

/// One finite number as an element of an array (so that the error's path
/// names its index).
pub(super) struct Finite(f64);

impl<'de> Deserialize<'de> for Finite {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        finite(deserializer).map(Finite)
    }
}

pub(super) fn finite_4x4<'de, D: Deserializer<'de>>(
    deserializer: D,
) -> Result<[[f64; 4]; 4], D::Error> {
    let rows: [[Finite; 4]; 4] = Deserialize::deserialize(deserializer)?;
    Ok(rows.map(|row| row.map(|x| x.0)))
}

pub(super) fn some_finite_4<'de, D: Deserializer<'de>>(
    deserializer: D,
) -> Result<Option<[f64; 4]>, D::Error> {
    let values: [Finite; 4] = Deserialize::deserialize(deserializer)?;
    Ok(Some(values.map(|x| x.0)))
}

/// A number, `null` read as NaN.
pub(super) fn number_or_nan<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(deserializer)?.unwrap_or(f64::NAN))
}

pub(super) fn three_or_nan<'de, D: Deserializer<'de>>(
    deserializer: D,
) -> Result<[f64; 3], D::Error> {
    let values: [Option<f64>; 3] = Deserialize::deserialize(deserializer)?;
    Ok(values.map(|x| x.unwrap_or(f64::NAN)))
}

pub(super) fn some_three_or_nan<'de, D: Deserializer<'de>>(
    deserializer: D,
) -> Result<Option<[f64; 3]>, D::Error> {
    three_or_nan(deserializer).map(Some)
}

pub(super) fn some_6x6_or_nan<'de, D: Deserializer<'de>>(
    deserializer: D,
) -> Result<Option<[[f64; 6]; 6]>, D::Error> {
    let rows: [[Option<f64>; 6]; 6] = Deserialize::deserialize(deserializer)?;
    Ok(Some(rows.map(|row| row.map(|x| x.unwrap_or(f64::NAN)))))
}
