//! Bit-exact serde of floats for checkpoints: a value is written as the 16 hex digits of its
//! IEEE-754 bits, so that a resumed study continues from exactly the state it stopped in
//! (decimal text that reads back to the same number is not guaranteed by every JSON parser).

use serde::{Deserialize, Deserializer, Serializer};

pub fn encode(x: f64) -> String {
    format!("{:016x}", x.to_bits())
}

/// A checkpoint's text that is no bit-exact float.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("'{text}' is not a 16-digit hex float: {error}")]
pub struct NotHexFloat {
    pub text: String,
    pub error: std::num::ParseIntError,
}

pub fn decode(s: &str) -> Result<f64, NotHexFloat> {
    u64::from_str_radix(s, 16)
        .map(f64::from_bits)
        .map_err(|error| NotHexFloat {
            text: s.into(),
            error,
        })
}

pub mod f64 {
    use super::*;
    pub fn serialize<S: Serializer>(x: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&encode(*x))
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        let s = String::deserialize(d)?;
        decode(&s).map_err(serde::de::Error::custom)
    }
}

pub mod vec {
    use super::*;
    use serde::ser::SerializeSeq;
    pub fn serialize<S: Serializer>(x: &[f64], s: S) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(x.len()))?;
        for v in x {
            seq.serialize_element(&encode(*v))?;
        }
        seq.end()
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        let v = Vec::<String>::deserialize(d)?;
        v.iter()
            .map(|s| decode(s).map_err(serde::de::Error::custom))
            .collect()
    }
}

pub mod vecvec {
    use super::*;
    use serde::ser::SerializeSeq;
    pub fn serialize<S: Serializer>(x: &[Vec<f64>], s: S) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(x.len()))?;
        for row in x {
            let enc: Vec<String> = row.iter().map(|v| encode(*v)).collect();
            seq.serialize_element(&enc)?;
        }
        seq.end()
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Vec<f64>>, D::Error> {
        let v = Vec::<Vec<String>>::deserialize(d)?;
        v.iter()
            .map(|row| {
                row.iter()
                    .map(|s| decode(s).map_err(serde::de::Error::custom))
                    .collect()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn round_trip_is_exact() {
        for x in [0.1 + 0.2, -1e-310, f64::MAX, 1.0 / 3.0, f64::INFINITY] {
            assert_eq!(
                super::decode(&super::encode(x)).unwrap().to_bits(),
                x.to_bits()
            );
        }
    }
}
