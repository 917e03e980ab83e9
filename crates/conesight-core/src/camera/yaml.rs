//! Typed YAML reading: a file's text into a `#[derive(Deserialize)]` struct (serde_yaml_ng),
//! with the serde error turned into a [`ConfigError`] that names the field.
//!
//! `serde_path_to_error` gives the path of the value that failed (`camera_matrix.data[4]`); a
//! missing field is reported at its parent with the field's name in the message. The path, with
//! list indices dropped and the missing field appended, is looked up in the caller's list of
//! field names: a known field gives [`ConfigError::Field`], anything else (a syntax error, a
//! document that is not a mapping) [`ConfigError::Yaml`] with the hint.

use serde::de::DeserializeOwned;

use crate::error::ConfigError;

/// Deserialises `text` into `T`; `fields` are the field paths errors may name (`a.b`).
pub(crate) fn from_str<T: DeserializeOwned>(
    text: &str,
    what: &str,
    hint: &'static str,
    fields: &[&'static str],
    expected: impl Fn(&str) -> &'static str,
) -> Result<T, ConfigError> {
    // Syntax first, so a broken file is a YAML error rather than a field's.
    let value: serde_yaml_ng::Value =
        serde_yaml_ng::from_str(text).map_err(|error| ConfigError::Yaml {
            what: what.to_owned(),
            message: error.to_string(),
            hint,
        })?;
    from_value(value, what, hint, fields, expected)
}

/// [`from_str`] on an already parsed YAML value (e.g. one entry of a larger file).
pub(super) fn from_value<T: DeserializeOwned>(
    value: serde_yaml_ng::Value,
    what: &str,
    hint: &'static str,
    fields: &[&'static str],
    expected: impl Fn(&str) -> &'static str,
) -> Result<T, ConfigError> {
    if !value.is_mapping() {
        return Err(ConfigError::Yaml {
            what: what.to_owned(),
            message: "the document is not a mapping".to_owned(),
            hint,
        });
    }
    serde_path_to_error::deserialize(value).map_err(|error| {
        let message = error.inner().to_string();
        let mut path: String = error
            .path()
            .to_string()
            .split('.')
            .map(|part| part.split('[').next().unwrap_or(part))
            .filter(|part| !part.is_empty() && *part != "?")
            .collect::<Vec<_>>()
            .join(".");
        if let Some(missing) = message
            .split_once("missing field `")
            .and_then(|(_, rest)| rest.split('`').next())
        {
            path = if path.is_empty() {
                missing.to_owned()
            } else {
                format!("{path}.{missing}")
            };
        }
        // An unknown key is reported at its own path; the field to blame is its parent.
        if message.contains("unknown field `") && !fields.contains(&path.as_str()) {
            path = path
                .rsplit_once('.')
                .map_or(String::new(), |(parent, _)| parent.to_owned());
        }
        match fields.iter().find(|field| **field == path) {
            Some(field) => ConfigError::Field {
                what: what.to_owned(),
                field,
                problem: problem(&message),
                expected: expected(field),
            },
            None => ConfigError::Yaml {
                what: what.to_owned(),
                message,
                hint,
            },
        }
    })
}

/// serde's message as a problem phrase: "is missing", or "is <what it got>".
fn problem(message: &str) -> String {
    if message.contains("missing field") {
        return "is missing".to_owned();
    }
    if let Some((_, rest)) = message.split_once("unknown field ") {
        return format!(
            "has the unknown key {}",
            rest.split(" at line ").next().unwrap_or(rest)
        );
    }
    // "invalid type: string \"x\", expected u32 at line 2 column 14"
    let message = message.split(" at line ").next().unwrap_or(message);
    match message.split_once(": ") {
        Some((_, rest)) => format!("is {}", rest.split(", expected").next().unwrap_or(rest)),
        None => format!("is invalid ({message})"),
    }
}
