//! PI GCS reply parsing, apart from the network link so that any text can be checked (and fuzzed):
//! each function takes the reply lines as read (continuation spaces trimmed) and returns the values
//! or a [`HwError::BadReply`] naming the controller, the command, the reply and what was expected.

use super::{parse_f64, parse_i64, HwError};

/// `*IDN?`: the identification string (the reply lines joined). Empty text or a SmarAct-style
/// reply (`:E-1,1`) is refused: the peer is not a GCS controller.
pub fn identity(controller: &str, lines: &[String]) -> Result<String, HwError> {
    let idn = lines.join(" ");
    if idn.trim().is_empty() || idn.starts_with(':') {
        return Err(HwError::bad_reply(
            controller,
            "*IDN?",
            &idn,
            "a PI identification string (is this a PI GCS controller?)",
        ));
    }
    Ok(idn)
}

/// `SAI?`: the axis identifiers, one per line; at least one.
pub fn axis_ids(controller: &str, lines: &[String]) -> Result<Vec<String>, HwError> {
    let ids: Vec<String> = lines.iter().map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect();
    if ids.is_empty() {
        return Err(HwError::bad_reply(controller, "SAI?", &lines.join("\\n"), "at least one axis identifier"));
    }
    Ok(ids)
}

/// `ERR?`: the pending error code. A number outside the i32 range is refused (truncating it could
/// turn an error into 0, "no error").
pub fn error_code(controller: &str, lines: &[String]) -> Result<i32, HwError> {
    let line = lines.first().map_or("", String::as_str);
    let code = parse_i64(controller, "ERR?", line, line)?;
    i32::try_from(code).map_err(|_| HwError::bad_reply(controller, "ERR?", line, "an error code within ±2147483647"))
}

/// A per-axis query (`POS? 1 2`): the value of each of `ids` from its `id=value` line, in the
/// order asked.
pub fn per_axis(controller: &str, command: &str, lines: &[String], ids: &[String]) -> Result<Vec<String>, HwError> {
    ids.iter()
        .map(|id| {
            lines
                .iter()
                .find_map(|l| {
                    let (k, v) = l.split_once('=')?;
                    (k.trim() == id).then(|| v.trim().to_string())
                })
                .ok_or_else(|| {
                    HwError::bad_reply(
                        controller,
                        command,
                        &lines.join("\\n"),
                        &format!("a line `{id}=<value>` for axis {id}"),
                    )
                })
        })
        .collect()
}

/// Per-axis flags (`ONT?`, `SVO?`): each value 0 or 1.
pub fn flags(controller: &str, command: &str, values: &[String]) -> Result<Vec<bool>, HwError> {
    values
        .iter()
        .map(|v| match v.as_str() {
            "0" => Ok(false),
            "1" => Ok(true),
            other => Err(HwError::bad_reply(controller, command, other, "0 or 1")),
        })
        .collect()
}

/// The value of a one-line `key=value` reply (or a bare value).
fn single_value(lines: &[String]) -> (&str, &str) {
    let line = lines.first().map_or("", String::as_str);
    (line, line.split_once('=').map_or(line, |p| p.1))
}

/// `DRL? <table>`: the number of points recorded.
pub fn count(controller: &str, command: &str, lines: &[String]) -> Result<usize, HwError> {
    let (line, v) = single_value(lines);
    let n = parse_i64(controller, command, line, v)?;
    usize::try_from(n).map_err(|_| HwError::bad_reply(controller, command, line, "a count ≥ 0"))
}

/// `TSP? <input>`: the input signal's value.
pub fn input_value(controller: &str, command: &str, lines: &[String]) -> Result<f64, HwError> {
    let (line, v) = single_value(lines);
    parse_f64(controller, command, line, v)
}

/// `SPA? <item> <param>` (GCS 2 parameter query, as PIPython's `qSPA` reads it): the value of the
/// line `<item> <param>=<value>`; the parameter id matches in any hexadecimal spelling.
pub fn param_value(
    controller: &str,
    command: &str,
    lines: &[String],
    item: &str,
    param: u32,
) -> Result<String, HwError> {
    lines
        .iter()
        .find_map(|l| {
            let (key, value) = l.split_once('=')?;
            let mut key = key.split_whitespace();
            let (i, p) = (key.next()?, key.next()?);
            let p = p.strip_prefix("0x").or_else(|| p.strip_prefix("0X")).unwrap_or(p);
            (i == item && u32::from_str_radix(p, 16).ok()? == param).then(|| value.trim().to_string())
        })
        .ok_or_else(|| {
            HwError::bad_reply(
                controller,
                command,
                &lines.join("\\n"),
                &format!("a line `{item} 0x{param:08X}=<value>`"),
            )
        })
}

/// The record and trigger options an `HDR?` reply lists (PIPython's `get_hdr_options`: a
/// `#RecordOptions` section, a `#TriggerOptions` section, lines `<number>=<text>`), and its
/// additional-information lines.
pub fn record_options(lines: &[String]) -> (Vec<u32>, Vec<u32>, Vec<String>) {
    let (mut record, mut trigger, mut info) = (vec![], vec![], vec![]);
    let mut section = 0;
    for line in lines.iter().map(|l| l.trim()) {
        if let Some(h) = line.strip_prefix('#') {
            section = if h.starts_with("RecordOptions") {
                1
            } else if h.starts_with("TriggerOptions") {
                2
            } else if h.starts_with("Additional information") {
                3
            } else {
                0
            };
            continue;
        }
        let option = line.split('=').next().and_then(|o| o.trim().parse::<u32>().ok());
        match (section, option) {
            (1, Some(o)) => record.push(o),
            (2, Some(o)) => trigger.push(o),
            (3, _) if !line.is_empty() => info.push(line.to_string()),
            _ => {}
        }
    }
    (record, trigger, info)
}

/// `DRR?`: a GCS data block, `#` header lines up to `# END_HEADER` then `tables` numbers per line;
/// the columns. `DIM` must equal `tables` and `NDATA` the number of data lines.
pub fn data_block(controller: &str, command: &str, lines: &[String], tables: usize) -> Result<Vec<Vec<f64>>, HwError> {
    let bad = |reply: &str, expected: &str| HwError::bad_reply(controller, command, reply, expected);
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); tables];
    let mut in_header = true;
    let mut ndata = None;
    for line in lines {
        if in_header {
            let Some(h) = line.strip_prefix('#') else {
                return Err(bad(line, "a GCS data header line starting with `#`"));
            };
            let h = h.trim();
            if h == "END_HEADER" {
                in_header = false;
            } else if let Some((k, v)) = h.split_once('=') {
                if k.trim() == "NDATA" {
                    ndata = Some(parse_i64(controller, command, line, v)?);
                } else if k.trim() == "DIM" && parse_i64(controller, command, line, v)? != tables as i64 {
                    return Err(bad(line, &format!("DIM = {tables}")));
                }
            }
            continue;
        }
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.len() != tables || tables == 0 {
            return Err(bad(line, &format!("{tables} numbers per data line")));
        }
        for (c, f) in columns.iter_mut().zip(fields) {
            c.push(parse_f64(controller, command, line, f)?);
        }
    }
    if in_header {
        return Err(bad(&lines.join("\\n"), "a header ending in `# END_HEADER`"));
    }
    let n = columns.first().map_or(0, Vec::len);
    if ndata.is_some_and(|d| d != n as i64) {
        return Err(bad(&format!("NDATA = {ndata:?}"), &format!("NDATA = {n} (the lines sent)")));
    }
    Ok(columns)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lines(text: &[&str]) -> Vec<String> {
        text.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn an_error_code_beyond_i32_is_refused_not_truncated_to_no_error() {
        // 2^32 truncated to i32 is 0: "no error" for a reply that is anything but.
        let e = error_code("pi", &lines(&["4294967296"])).unwrap_err().to_string();
        assert!(e.contains("ERR?") && e.contains("4294967296") && e.contains("2147483647"), "{e}");
        assert_eq!(error_code("pi", &lines(&["216"])).unwrap(), 216);
        assert!(error_code("pi", &[]).is_err());
    }

    #[test]
    fn parameters_and_record_options_parse() {
        let l = lines(&["1 0x0E000200=2e-05"]);
        assert_eq!(param_value("pi", "SPA?", &l, "1", 0x0E00_0200).unwrap(), "2e-05");
        let l = lines(&["1 0xe000200=2e-05"]);
        assert_eq!(param_value("pi", "SPA?", &l, "1", 0x0E00_0200).unwrap(), "2e-05");
        assert!(param_value("pi", "SPA?", &l, "1", 0x1600_0200).is_err());
        let hdr = lines(&[
            "#RecordOptions",
            "0=Nothing",
            "17=Normalized value of input signal channel",
            "#TriggerOptions",
            "1=any command changing position",
            "3=external trigger",
            "#Additional information",
            "32768 datapoints per table",
        ]);
        let (r, t, i) = record_options(&hdr);
        assert_eq!((r, t, i.len()), (vec![0, 17], vec![1, 3], 1));
    }

    #[test]
    fn data_blocks_parse_or_say_what_is_wrong() {
        let ok = lines(&["# DIM = 2", "# NDATA = 2", "# END_HEADER", "1 2", "3 4e-3"]);
        assert_eq!(data_block("pi", "DRR?", &ok, 2).unwrap(), vec![vec![1.0, 3.0], vec![2.0, 4e-3]]);
        let short = lines(&["# NDATA = 3", "# END_HEADER", "1 2"]);
        assert!(data_block("pi", "DRR?", &short, 2).unwrap_err().to_string().contains("NDATA"));
        assert!(data_block("pi", "DRR?", &lines(&["# END_HEADER", "1"]), 0).is_err());
        assert!(data_block("pi", "DRR?", &lines(&["1 2"]), 2).is_err());
    }
}
