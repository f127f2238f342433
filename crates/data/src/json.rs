//! Reading a transforms file: the parse, and typed look-ups that name the key at fault
//! (`frames[3].fl_x`) in their errors.

use std::path::Path;

use serde_json::{Map, Value};

use crate::error::{one_line, DataError};

/// The parsed JSON document of `path`. Errors: an unreadable file, invalid JSON (with its line
/// and column), a top level that is not an object.
pub(crate) fn read(path: &Path) -> Result<Map<String, Value>, DataError> {
    let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    let value: Value = serde_json::from_str(&text).map_err(|e| DataError::Json {
        path: path.to_path_buf(),
        line: e.line(),
        column: e.column(),
        message: one_line(e),
    })?;
    match value {
        Value::Object(map) => Ok(map),
        _ => Err(DataError::WrongType {
            path: path.to_path_buf(),
            key: "(top level)".into(),
            expected: "an object",
        }),
    }
}

/// A JSON object of a transforms file, and where it sits in it (`""` for the top level,
/// `"frames[3]."` for a frame) to name keys in errors.
#[derive(Clone, Copy)]
pub(crate) struct Obj<'a> {
    pub path: &'a Path,
    pub map: &'a Map<String, Value>,
    pub prefix: &'a str,
}

impl<'a> Obj<'a> {
    /// The full name of `key`, as errors print it.
    pub fn name(&self, key: &str) -> String {
        format!("{}{}", self.prefix, key)
    }

    pub fn get(&self, key: &str) -> Option<&'a Value> {
        self.map.get(key).filter(|v| !v.is_null())
    }

    pub fn missing(&self, key: &str) -> DataError {
        DataError::MissingKey {
            path: self.path.to_path_buf(),
            key: self.name(key),
        }
    }

    pub fn wrong_type(&self, key: &str, expected: &'static str) -> DataError {
        DataError::WrongType {
            path: self.path.to_path_buf(),
            key: self.name(key),
            expected,
        }
    }

    pub fn bad_value(&self, key: &str, value: f64, rule: &'static str) -> DataError {
        DataError::BadValue {
            path: self.path.to_path_buf(),
            key: self.name(key),
            value,
            rule,
        }
    }

    /// A number, if the key is present.
    pub fn number(&self, key: &str) -> Result<Option<f64>, DataError> {
        match self.get(key) {
            None => Ok(None),
            Some(v) => v.as_f64().map(Some).ok_or_else(|| self.wrong_type(key, "a number")),
        }
    }

    /// A finite number, if the key is present.
    pub fn finite(&self, key: &str) -> Result<Option<f64>, DataError> {
        match self.number(key)? {
            Some(v) if !v.is_finite() => Err(self.bad_value(key, v, "must be finite")),
            v => Ok(v),
        }
    }

    /// A positive finite number, if the key is present (focal lengths, fields of view).
    pub fn positive(&self, key: &str) -> Result<Option<f64>, DataError> {
        match self.number(key)? {
            Some(v) if !(v.is_finite() && v > 0.0) => Err(self.bad_value(key, v, "must be positive and finite")),
            v => Ok(v),
        }
    }

    /// A positive whole number (`800` or `800.0`), if the key is present (image sizes).
    pub fn size(&self, key: &str) -> Result<Option<usize>, DataError> {
        match self.number(key)? {
            None => Ok(None),
            Some(v) if v.is_finite() && v >= 1.0 && v.fract() == 0.0 && v <= u32::MAX as f64 => Ok(Some(v as usize)),
            Some(v) => Err(self.bad_value(key, v, "must be a positive whole number")),
        }
    }

    /// A string, if the key is present.
    pub fn string(&self, key: &str) -> Result<Option<&'a str>, DataError> {
        match self.get(key) {
            None => Ok(None),
            Some(v) => v.as_str().map(Some).ok_or_else(|| self.wrong_type(key, "a string")),
        }
    }
}

/// The non-empty `frames` array of a transforms file, each frame an object. Errors: no
/// `frames`, not an array, empty, a frame that is not an object.
pub(crate) fn frames<'a>(
    path: &'a Path,
    root: &'a Map<String, Value>,
) -> Result<Vec<&'a Map<String, Value>>, DataError> {
    let top = Obj {
        path,
        map: root,
        prefix: "",
    };
    let list = top
        .get("frames")
        .ok_or_else(|| top.missing("frames"))?
        .as_array()
        .ok_or_else(|| top.wrong_type("frames", "an array"))?;
    if list.is_empty() {
        return Err(DataError::NoFrames {
            path: path.to_path_buf(),
        });
    }
    list.iter()
        .enumerate()
        .map(|(i, f)| {
            f.as_object().ok_or_else(|| DataError::WrongType {
                path: path.to_path_buf(),
                key: format!("frames[{i}]"),
                expected: "an object",
            })
        })
        .collect()
}
