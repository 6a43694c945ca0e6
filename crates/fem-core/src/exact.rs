//! Fixed-length arrays (`[f64; 3]`, a keyframe's `[f64; 4]`, …) read with their length
//! checked, for `#[serde(deserialize_with = …)]`. The `toml` crate hands serde an array as a
//! tuple and lets the array's visitor stop at its length, so `acceleration = [0,0, -9,81, 0,0]`
//! (decimal commas pasted into a list) was read as `[0, 0, -9]` without a word; too few values
//! were refused. These read the values, then say how many there were when there are more.
//! Binary formats (postcard, whose tuples carry no length) read exactly as before.

use std::fmt;
use std::marker::PhantomData;

use serde::de::{Deserialize, Deserializer, Error, IgnoredAny, SeqAccess, Visitor};

/// An `[T; N]` whose reading refuses a list of any other length.
struct Exact<T, const N: usize>([T; N]);

impl<'de, T: Deserialize<'de>, const N: usize> Deserialize<'de> for Exact<T, N> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Values<T, const N: usize>(PhantomData<T>);
        impl<'de, T: Deserialize<'de>, const N: usize> Visitor<'de> for Values<T, N> {
            type Value = [T; N];

            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "a list of {N} values")
            }

            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<[T; N], A::Error> {
                let mut values = Vec::with_capacity(N);
                while values.len() < N {
                    match seq.next_element()? {
                        Some(v) => values.push(v),
                        None => return Err(A::Error::invalid_length(values.len(), &self)),
                    }
                }
                let mut extra = 0;
                while seq.next_element::<IgnoredAny>()?.is_some() {
                    extra += 1;
                }
                if extra > 0 {
                    return Err(A::Error::invalid_length(N + extra, &self));
                }
                values
                    .try_into()
                    .map_err(|_| A::Error::custom("a list of the wrong length"))
            }
        }
        d.deserialize_tuple(N, Values::<T, N>(PhantomData))
            .map(Exact)
    }
}

/// `[T; N]` of exactly `N` values.
pub fn array<'de, D, T, const N: usize>(d: D) -> Result<[T; N], D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    Exact::<T, N>::deserialize(d).map(|e| e.0)
}

/// An optional `[T; N]` of exactly `N` values (with `#[serde(default)]` when it may be left
/// out).
pub fn option<'de, D, T, const N: usize>(d: D) -> Result<Option<[T; N]>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    Option::<Exact<T, N>>::deserialize(d).map(|o| o.map(|e| e.0))
}

/// A list of `[T; N]` rows of exactly `N` values each.
pub fn rows<'de, D, T, const N: usize>(d: D) -> Result<Vec<[T; N]>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    Vec::<Exact<T, N>>::deserialize(d).map(|v| v.into_iter().map(|e| e.0).collect())
}

#[cfg(test)]
mod tests {
    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    struct Sample {
        #[serde(deserialize_with = "super::array")]
        g: [f64; 3],
        #[serde(default, deserialize_with = "super::option")]
        range: Option<[f64; 2]>,
        #[serde(deserialize_with = "super::rows")]
        keyframes: Vec<[f64; 4]>,
    }

    fn read(text: &str) -> Result<Sample, String> {
        toml::from_str(text).map_err(|e| e.message().to_string())
    }

    /// Lists of the right length read; longer and shorter ones are refused with their length.
    #[test]
    fn lists_of_another_length_are_refused() {
        let good = read("g = [0, -9.81, 0]\nkeyframes = [[0, 1, 2, 3]]").unwrap();
        assert_eq!(good.g, [0.0, -9.81, 0.0]);
        assert_eq!(good.range, None);
        let e = read("g = [0,0, -9,81, 0,0]\nkeyframes = []").unwrap_err();
        assert_eq!(e, "invalid length 6, expected a list of 3 values");
        let e = read("g = [0, 1]\nkeyframes = []").unwrap_err();
        assert_eq!(e, "invalid length 2, expected a list of 3 values");
        let e = read("g = [0, 1, 2]\nrange = [1, 2, 3]\nkeyframes = []").unwrap_err();
        assert_eq!(e, "invalid length 3, expected a list of 2 values");
        let e = read("g = [0, 1, 2]\nkeyframes = [[0, 1, 2, 3, 4]]").unwrap_err();
        assert_eq!(e, "invalid length 5, expected a list of 4 values");
    }

    /// A binary format, whose tuples carry no length, reads what it wrote.
    #[test]
    fn binary_formats_read_as_before() {
        let s = Sample {
            g: [1.0, 2.0, 3.0],
            range: Some([4.0, 5.0]),
            keyframes: vec![[6.0, 7.0, 8.0, 9.0]; 2],
        };
        let bytes = postcard::to_allocvec(&s).unwrap();
        assert_eq!(postcard::from_bytes::<Sample>(&bytes).unwrap(), s);
        let json = serde_json::to_string(&s).unwrap();
        assert_eq!(serde_json::from_str::<Sample>(&json).unwrap(), s);
    }
}
