//! The keys a serde struct reads, taken from its `Deserialize` impl, so that a key list is
//! never written by hand beside the struct that defines the keys.

use serde::de::{self, DeserializeOwned, Deserializer, Visitor};

/// The field names `T` deserialises (as written in a config: after `rename`), in declaration
/// order; empty when `T` is not a plain struct (a `flatten`ed field makes serde read a map,
/// and `skip`ped fields are not read at all, so neither is listed).
pub fn struct_keys<T: DeserializeOwned>() -> &'static [&'static str] {
    let mut fields: &'static [&'static str] = &[];
    // The capture always fails (it has no data to give), having recorded the fields.
    let _ = T::deserialize(Capture(&mut fields));
    fields
}

/// A deserializer that records the fields a struct asks for and gives nothing.
struct Capture<'a>(&'a mut &'static [&'static str]);

impl<'de> Deserializer<'de> for Capture<'_> {
    type Error = de::value::Error;

    fn deserialize_any<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value, Self::Error> {
        Err(de::Error::custom("not a struct"))
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        fields: &'static [&'static str],
        _visitor: V,
    ) -> Result<V::Value, Self::Error> {
        *self.0 = fields;
        Err(de::Error::custom("fields recorded"))
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf
        option unit unit_struct newtype_struct seq tuple tuple_struct map enum identifier
        ignored_any
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_the_fields_as_written_and_nothing_for_other_types() {
        #[derive(serde::Deserialize)]
        #[allow(dead_code)]
        struct Example {
            first: u8,
            #[serde(rename = "second_key")]
            second: Option<String>,
            #[serde(skip)]
            hidden: bool,
        }
        assert_eq!(struct_keys::<Example>(), ["first", "second_key"]);
        assert!(struct_keys::<u8>().is_empty());
        assert!(struct_keys::<Vec<String>>().is_empty());
    }
}
