//! Scene-file plumbing shared by the coordinator and the engines (no transport, no physics):
//! the scene error with its place in the file ([`SceneError`]), reading one node's table out of
//! the whole scene file with the file's own line numbers in errors ([`named_table`]), field paths
//! ([`Seg`], [`split_path`], [`path_string`]) and where they are in the text ([`locate`],
//! [`path_at`], [`line_col`]).
//!
//! A scene names each solver node by id; a node reads the top-level table of its id (`[dem]`,
//! `[fem]`, `[sleeper_left]`, ...), so two FEM structures in one scene are two tables of the
//! same schema.

use serde::de::{DeserializeOwned, IgnoredAny, MapAccess, Visitor};
use serde::Deserializer as _;

/// A scene-file error with its place: the file (empty when the reader only has the text, as a
/// node has), 1-based line and column (0: the file as a whole), the dotted field path (empty
/// when unknown) and the message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SceneError {
    pub file: String,
    pub line: usize,
    pub column: usize,
    pub field: String,
    pub message: String,
}

impl SceneError {
    /// An error at byte `offset` of `text`.
    pub fn at(
        text: &str,
        offset: usize,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        let (line, column) = line_col(text, offset);
        SceneError {
            file: String::new(),
            line,
            column,
            field: field.into(),
            message: message.into(),
        }
    }

    /// The same error, naming the file.
    pub fn in_file(mut self, file: impl Into<String>) -> Self {
        self.file = file.into();
        self
    }
}

/// With a file: `file:line:column: field: message` (the form compilers use); without one:
/// `line L, column C: field: message` (a node's error, which the node prefixes with the file).
impl std::fmt::Display for SceneError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let field = if self.field.is_empty() || self.message.starts_with(&self.field) {
            String::new()
        } else {
            format!("{}: ", self.field)
        };
        match (self.file.is_empty(), self.line) {
            (true, 0) => write!(f, "{field}{}", self.message),
            (true, _) => write!(
                f,
                "line {}, column {}: {field}{}",
                self.line, self.column, self.message
            ),
            (false, 0) => write!(f, "{}: {field}{}", self.file, self.message),
            (false, _) => write!(
                f,
                "{}:{}:{}: {field}{}",
                self.file, self.line, self.column, self.message
            ),
        }
    }
}

impl std::error::Error for SceneError {}

/// 1-based line and column (in characters) of a byte offset in `text`.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map(|i| i + 1).unwrap_or(0);
    (line, text[line_start..offset].chars().count() + 1)
}

/// A step of a field path: a key or an array index.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Seg {
    Key(String),
    Index(usize),
}

/// `fem.loads[2].on.box` → keys and indices.
pub fn split_path(path: &str) -> Vec<Seg> {
    let mut out = Vec::new();
    for part in path.split('.') {
        let mut rest = part;
        if let Some(p) = rest.find('[') {
            out.push(Seg::Key(rest[..p].to_string()));
            rest = &rest[p..];
            while let Some(stripped) = rest.strip_prefix('[') {
                let end = stripped.find(']').unwrap_or(stripped.len());
                if let Ok(i) = stripped[..end].parse() {
                    out.push(Seg::Index(i));
                }
                rest = stripped.get(end + 1..).unwrap_or("");
            }
        } else {
            out.push(Seg::Key(rest.to_string()));
        }
    }
    out
}

/// Keys and indices → `fem.loads[2].on.box`.
pub fn path_string(path: &[Seg]) -> String {
    let mut s = String::new();
    for seg in path {
        match seg {
            Seg::Key(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            Seg::Index(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

/// Byte span in `text` of the key (or array element) at `path`, or of the deepest prefix of it
/// that exists; the whole document's span when not even the first key does. `None` when `text`
/// is not TOML.
pub fn locate(text: &str, path: &[Seg]) -> Option<std::ops::Range<usize>> {
    use toml::de::{DeTable, DeValue};
    let doc = DeTable::parse(text).ok()?;
    let mut best = doc.span();
    let mut cur: Option<&toml::Spanned<DeValue>> = None;
    let root = doc.get_ref();
    for (depth, seg) in path.iter().enumerate() {
        let next = match (seg, cur) {
            (Seg::Key(k), None) if depth == 0 => root
                .iter()
                .find(|(key, _)| key.get_ref().as_ref() == k.as_str())
                .map(|(key, v)| {
                    best = key.span();
                    v
                }),
            (Seg::Key(k), Some(v)) => v.get_ref().as_table().and_then(|t| {
                t.iter()
                    .find(|(key, _)| key.get_ref().as_ref() == k.as_str())
                    .map(|(key, v)| {
                        best = key.span();
                        v
                    })
            }),
            (Seg::Index(i), Some(v)) => v.get_ref().as_array().and_then(|a| {
                a.get(*i).inspect(|v| {
                    best = v.span();
                })
            }),
            _ => None,
        };
        match next {
            Some(v) => cur = Some(v),
            None => break,
        }
    }
    Some(best)
}

/// Dotted path of the innermost key whose key or value span contains `offset` (the whole tree
/// is searched: tables opened by separate headers do not nest by span).
pub fn path_at(text: &str, offset: usize) -> Option<String> {
    use toml::de::{DeTable, DeValue};
    fn walk_table(
        t: &DeTable,
        offset: usize,
        prefix: &str,
        depth: usize,
        best: &mut Option<(usize, String)>,
    ) {
        for (k, v) in t.iter() {
            let path = if prefix.is_empty() {
                k.get_ref().to_string()
            } else {
                format!("{prefix}.{}", k.get_ref())
            };
            if (k.span().contains(&offset) || v.span().contains(&offset))
                && best.as_ref().is_none_or(|(d, _)| depth >= *d)
            {
                *best = Some((depth, path.clone()));
            }
            walk_value(v, offset, &path, depth + 1, best);
        }
    }
    fn walk_value(
        v: &toml::Spanned<DeValue>,
        offset: usize,
        path: &str,
        depth: usize,
        best: &mut Option<(usize, String)>,
    ) {
        match v.get_ref() {
            DeValue::Table(t) => walk_table(t, offset, path, depth, best),
            DeValue::Array(a) => {
                for (i, e) in a.iter().enumerate() {
                    walk_value(e, offset, &format!("{path}[{i}]"), depth, best);
                }
            }
            _ => {}
        }
    }
    let root = DeTable::parse(text).ok()?;
    let mut best: Option<(usize, String)> = None;
    walk_table(root.get_ref(), offset, "", 0, &mut best);
    best.map(|(_, p)| p)
}

/// The top-level table `name` of a whole TOML document, deserialised as `T`; the other tables
/// are skipped unread. `Ok(None)` when there is no such table. Errors carry spans into `text`
/// (the document is parsed as a whole, so lines and columns are the file's).
pub fn named_table<T: DeserializeOwned>(
    text: &str,
    name: &str,
) -> Result<Option<T>, toml::de::Error> {
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
    fn lines_and_columns_are_one_based_and_count_characters() {
        assert_eq!(line_col("ab\ncd", 0), (1, 1));
        assert_eq!(line_col("ab\ncd", 4), (2, 2));
        assert_eq!(line_col("ab", 99), (1, 3));
        assert_eq!(line_col("µs = 1", 2), (1, 2));
        assert_eq!(
            line_col("µs = 1", 1),
            (1, 1),
            "inside a character: its start"
        );
    }

    #[test]
    fn paths_split_join_and_are_found_in_the_text() {
        let text = "[fem]\nmesh = 1\n[[fem.loads]]\non = 1\n[[fem.loads]]\non = { box = 2 }\n";
        let p = split_path("fem.loads[1].on.box");
        assert_eq!(path_string(&p), "fem.loads[1].on.box");
        let span = locate(text, &p).unwrap();
        assert_eq!(line_col(text, span.start), (6, 8));
        // a missing leaf: the deepest prefix that exists
        let span = locate(text, &split_path("fem.mesh.size")).unwrap();
        assert_eq!(line_col(text, span.start), (2, 1));
        assert_eq!(
            path_at(text, text.find("box").unwrap()).as_deref(),
            Some("fem.loads[1].on.box")
        );
    }

    #[test]
    fn errors_read_like_compiler_messages_with_a_file_and_like_node_messages_without() {
        let text = "[scene]\nend_time = 1\n";
        let e = SceneError::at(text, 8, "scene.end_time", "must be positive");
        assert_eq!(
            e.to_string(),
            "line 2, column 1: scene.end_time: must be positive"
        );
        let e = e.in_file("s.toml");
        assert_eq!(
            e.to_string(),
            "s.toml:2:1: scene.end_time: must be positive"
        );
        let whole = SceneError {
            line: 0,
            ..e.clone()
        };
        assert_eq!(
            whole.to_string(),
            "s.toml: scene.end_time: must be positive"
        );
        // a message that starts with its path does not repeat it
        let e = SceneError::at(text, 0, "dem.x", "dem.x: unknown");
        assert_eq!(e.to_string(), "line 1, column 1: dem.x: unknown");
    }
}
