//! Tables transcribed by hand where no raw results were kept, or where no view makes them from
//! the raw records they name (`{"transcribed": {source, commit, host, device, note, raw},
//! "columns", "align", "rows"}`): shown as recorded, with a line naming where they came from
//! (see [`super::markdown`]).

use serde_json::Value;

/// What is made, or what is wrong with the file (the caller names the file and the line).
type Made<T> = std::result::Result<T, String>;

/// A table's header, alignments and rows.
type Table = (Vec<String>, Vec<char>, Vec<Vec<String>>);

/// A transcribed file's table as recorded: its header, alignments (`r` right, `c` centre, else
/// left) and rows.
pub(super) fn table(json: &Value) -> Made<Table> {
    let strings = |v: &Value, what: &str| -> Made<Vec<String>> {
        v.as_array()
            .ok_or_else(|| format!("transcribed {what}: not a list"))?
            .iter()
            .map(|c| {
                c.as_str()
                    .map(str::to_string)
                    .ok_or_else(|| format!("transcribed {what}: cells are strings"))
            })
            .collect()
    };
    let header = strings(&json["columns"], "columns")?;
    let align: Vec<char> = match &json["align"] {
        Value::Null => Vec::new(),
        v => strings(v, "align")?
            .iter()
            .map(|a| a.chars().next().unwrap_or('l'))
            .collect(),
    };
    let rows = json["rows"]
        .as_array()
        .ok_or_else(|| "transcribed rows: not a list".to_string())?
        .iter()
        .map(|r| strings(r, "rows"))
        .collect::<Made<Vec<_>>>()?;
    if let Some(bad) = rows.iter().find(|r| r.len() != header.len()) {
        return Err(format!(
            "a transcribed row has {} cells for {} columns: {bad:?}",
            bad.len(),
            header.len()
        ));
    }
    Ok((header, align, rows))
}

/// The line under a transcribed table: its source, raw records (or none kept), commit, host,
/// device and note.
pub(super) fn caption(t: &Value) -> Made<String> {
    let field = |k: &str| -> Made<String> {
        t[k].as_str()
            .map(str::to_string)
            .ok_or_else(|| format!("transcribed.{k}: required, a string"))
    };
    let commit = match &t["commit"] {
        Value::String(c) => format!("measured at {c}"),
        Value::Null => "measured at a commit not recorded".into(),
        _ => return Err("transcribed.commit: a string or null".to_string()),
    };
    let note = t["note"].as_str().map_or(String::new(), |n| {
        format!(" {}", n.trim_end_matches('.').to_string() + ".")
    });
    let raw = match &t["raw"] {
        Value::Null => "no raw file kept".to_string(),
        Value::Array(files) => {
            let files = files
                .iter()
                .map(|f| f.as_str().map(str::to_string))
                .collect::<Option<Vec<_>>>()
                .filter(|f| !f.is_empty())
                .ok_or("transcribed.raw: a list of file paths")?;
            format!("raw records: {}", files.join(", "))
        }
        _ => return Err("transcribed.raw: a list of file paths".to_string()),
    };
    Ok(format!(
        "Transcribed from {} ({raw}): {commit}; host: {}; device: {}.{note}",
        field("source")?,
        field("host")?,
        field("device")?
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A transcription names its raw records where they were kept, else says none was; a `raw`
    /// that is not a list of paths is refused.
    #[test]
    fn a_transcription_names_its_raw_records() {
        let mut t = serde_json::json!({
            "source": "s", "commit": "abc", "host": "h", "device": "d"
        });
        let line = caption(&t).unwrap();
        assert!(line.contains("(no raw file kept)"), "{line}");
        t["raw"] = serde_json::json!(["docs/results/a.json", "docs/results/b.json"]);
        let line = caption(&t).unwrap();
        assert!(
            line.contains("(raw records: docs/results/a.json, docs/results/b.json)"),
            "{line}"
        );
        for bad in [
            serde_json::json!("a.json"),
            serde_json::json!([]),
            serde_json::json!([1]),
        ] {
            t["raw"] = bad;
            assert!(caption(&t).is_err());
        }
    }
}
