//! Scene-file plumbing shared by the coordinator and the engines (no transport, no physics):
//! reading one node's table out of the whole scene file with the file's own line numbers in
//! errors, and turning byte offsets into lines and columns.
//!
//! A scene names each solver node by id; a node reads the top-level table of its id (`[dem]`,
//! `[fem]`, `[sleeper_left]`, ...), so two FEM structures in one scene are two tables of the
//! same schema.

use serde::de::{DeserializeOwned, IgnoredAny, MapAccess, Visitor};
use serde::Deserializer as _;

/// 1-based line and column of a byte offset in `text`.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let column = before.rfind('\n').map(|i| offset - i).unwrap_or(offset + 1);
    (line, column)
}

/// The top-level table `name` of a whole TOML document, deserialised as `T`; the other tables
/// are skipped unread. `Ok(None)` when there is no such table. Errors carry spans into `text`
/// (the document is parsed as a whole, so lines and columns are the file's).
pub fn named_table<T: DeserializeOwned>(text: &str, name: &str) -> Result<Option<T>, toml::de::Error> {
    struct Pick<'a, T>(&'a str, std::marker::PhantomData<T>);
    impl<'de, T: DeserializeOwned> Visitor<'de> for Pick<'_, T> {
        type Value = Option<T>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a TOML document")
        }
        fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Option<T>, A::Error> {
            let mut out = None;
            while let Some(key) = map.next_key::<String>()? {
                if key == self.0 {
                    out = Some(map.next_value::<T>()?);
                } else {
                    map.next_value::<IgnoredAny>()?;
                }
            }
            Ok(out)
        }
    }
    let de = toml::de::Deserializer::parse(text)?;
    de.deserialize_map(Pick(name, std::marker::PhantomData))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(serde::Deserialize, Debug, PartialEq)]
    #[serde(deny_unknown_fields)]
    struct T {
        a: f64,
    }

    #[test]
    fn a_named_table_is_read_and_errors_point_into_the_file() {
        let text = "[scene]\nx = 1\n[left]\na = 1.5\n[right]\na = 2.5\n";
        assert_eq!(named_table::<T>(text, "right").unwrap(), Some(T { a: 2.5 }));
        assert_eq!(named_table::<T>(text, "left").unwrap(), Some(T { a: 1.5 }));
        assert_eq!(named_table::<T>(text, "none").unwrap(), None);
        let bad = "[scene]\nx = 1\n[left]\na = 1.5\nb = 3\n";
        let e = named_table::<T>(bad, "left").unwrap_err();
        assert!(e.message().contains("unknown field `b`"), "{e}");
        let (line, _) = line_col(bad, e.span().unwrap().start);
        assert_eq!(line, 5);
        // a broken document elsewhere is still an error (the file must be valid TOML)
        assert!(named_table::<T>("[left]\na = 1\n[x\n", "left").is_err());
    }

    #[test]
    fn lines_and_columns_are_one_based() {
        assert_eq!(line_col("ab\ncd", 0), (1, 1));
        assert_eq!(line_col("ab\ncd", 4), (2, 2));
        assert_eq!(line_col("ab", 99), (1, 3));
    }
}
