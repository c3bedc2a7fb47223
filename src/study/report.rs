//! A study's Markdown page: how it was run, the figure, its table (median and spread of every
//! measurement) and what the numbers say against the paper.

use std::collections::BTreeSet;
use std::fmt::Write as _;

use super::record::{Recorder, Row};

/// What a study says about itself beside its rows.
pub struct Page<'a> {
    /// The study's name.
    pub study: &'a str,
    /// The page's title.
    pub title: &'a str,
    /// What the paper measures and shows (the figure or table).
    pub paper: &'a str,
    /// The command line that ran it.
    pub command: &'a str,
    /// What the rows say against the paper, one paragraph each.
    pub notes: &'a [String],
    /// Markdown of the study's own after the notes (a table shaped as its question is), or
    /// empty.
    pub extra: &'a str,
    /// The study stopped early: why.
    pub failure: Option<&'a str>,
}

/// A number with four significant digits (no exponent in the usual ranges).
pub fn number(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-4..1e7).contains(&a) {
        format!("{v:.3e}")
    } else {
        let digits = (3 - a.log10().floor() as i32).clamp(0, 7) as usize;
        format!("{v:.digits$}")
    }
}

/// The Markdown page for the rows `recorder` holds.
pub fn markdown(page: &Page<'_>, recorder: &Recorder) -> String {
    let rows = recorder.rows();
    let m = recorder.machine();
    let mut out = String::new();
    let _ = writeln!(out, "# {}\n", page.title);
    let _ = writeln!(out, "{}\n", page.paper);
    let _ = writeln!(out, "```sh\n{}\n```\n", page.command);
    let _ = writeln!(
        out,
        "Run {} on {} ({}, {} threads).",
        m.date, m.host, m.cpu, m.threads
    );
    let mut devices = BTreeSet::new();
    for r in rows {
        devices.insert((
            r.device.backend.clone(),
            r.device.adapter.clone(),
            r.device.driver.clone(),
            r.device.timer,
        ));
    }
    for (backend, adapter, driver, timer) in &devices {
        let driver = if driver.is_empty() {
            String::new()
        } else {
            format!(", {driver}")
        };
        let _ = writeln!(out, "- `{backend}`: {adapter}{driver}; times by {timer}");
    }
    if devices.iter().any(|d| d.1.contains("llvmpipe")) {
        let _ = writeln!(
            out,
            "\nllvmpipe is Mesa's software Vulkan (lavapipe): the GPU backends run on the same \
             CPU cores as the `cpu` backend, so their ratios say how GPU code runs on a CPU, not \
             what RT hardware does."
        );
    }
    if let Some(why) = page.failure {
        let _ = writeln!(
            out,
            "\n**The study stopped early: {why}.** The rows below are those measured before."
        );
    }
    let _ = writeln!(out, "\n![{}]({}.png)\n", page.title, page.study);
    if !page.notes.is_empty() {
        let _ = writeln!(out, "What it says:\n");
        for n in page.notes {
            let _ = writeln!(out, "- {n}");
        }
        let _ = writeln!(out);
    }
    if !page.extra.is_empty() {
        let _ = writeln!(out, "{}", page.extra);
    }
    // Settings the same in every row are stated once; those that vary are columns.
    let keys = recorder.settings();
    let constant: Vec<(&str, String)> = keys
        .iter()
        .filter_map(|k| {
            let values: BTreeSet<&str> = rows.iter().filter_map(|r| r.setting(k)).collect();
            (values.len() == 1).then(|| (*k, values.into_iter().next().unwrap_or("").to_owned()))
        })
        .collect();
    let varying: Vec<&str> = keys
        .iter()
        .copied()
        .filter(|k| !constant.iter().any(|(c, _)| c == k))
        .collect();
    if !constant.is_empty() {
        let _ = writeln!(
            out,
            "Settings of every row: {}.\n",
            constant
                .iter()
                .map(|(k, v)| format!("{k} = {v}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let _ = write!(out, "| backend | variant | data | step | N |");
    for k in &varying {
        let _ = write!(out, " {k} |");
    }
    let _ = writeln!(out, " metric | median | spread (min – max) | repetitions |");
    let _ = write!(out, "|---|---|---|---|---|");
    for _ in &varying {
        let _ = write!(out, "---|");
    }
    let _ = writeln!(out, "---|---|---|---|");
    for r in rows {
        table_row(&mut out, r, &varying);
    }
    let _ = writeln!(
        out,
        "\nEvery repetition's value is in `{}.csv` (one row per measurement).",
        page.study
    );
    out
}

fn table_row(out: &mut String, r: &Row, varying: &[&str]) {
    let _ = write!(
        out,
        "| {} | {} | {} | {} | {} |",
        r.device.backend, r.variant, r.data, r.step, r.n
    );
    for k in varying {
        let _ = write!(out, " {} |", r.setting(k).unwrap_or(""));
    }
    let _ = writeln!(
        out,
        " {} ({}) | {} | {} – {} | {} |",
        r.metric,
        r.unit,
        number(r.median()),
        number(r.min()),
        number(r.max()),
        r.values.len()
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_keep_four_significant_digits() {
        assert_eq!(number(1234.5678), "1235");
        assert_eq!(number(12.345678), "12.35");
        assert_eq!(number(0.0123456), "0.01235");
        assert_eq!(number(0.0), "0");
        assert_eq!(number(3.2e9), "3.200e9");
    }
}
