//! `fogray-lab bench --markdown DIR [--readme FILE]`: the measurements as a generated report
//! (`DIR/bench-composite.md` or `DIR/bench-grid.md`, stamped with date, machine and command),
//! and the headline rows of it in the README's marked block, so that no figure on the front
//! page is typed by hand.

use std::path::Path;

use crate::stamp::Stamp;

use crate::bench::Measurement;
use crate::error::LabError;
use crate::grid_bench::GridMeasurement;

/// The full report: the stamp, then the text tables in a code block.
pub fn report(title: &str, stamp: &Stamp, tables: &str) -> String {
    format!(
        "# {title}\n\n{}\n\nWhat each column means: `docs/performance.md`. This machine is noisy: compare within one report, and read the spread.\n\n```\n{}\n```\n",
        stamp.markdown(),
        tables.trim_end()
    )
}

/// The composite's headline: 65536 rays x 64 samples (or the first workload measured), f32
/// and f64, the fused op on all threads against the taped twins (also on all threads).
pub fn composite_headline(results: &[Measurement], stamp: &Stamp) -> String {
    let Some(first) = results.first() else {
        return String::new();
    };
    let (rays, samples) = results
        .iter()
        .find(|m| m.rays == 65536 && m.samples == 64)
        .map_or((first.rays, first.samples), |m| (m.rays, m.samples));
    let mut s = format!(
        "Composite, {rays} rays x {samples} samples, forward + backward (M samples/s; errors against an f64 reference, element-wise):\n\n| method | precision | threads | M samples/s | in one pass | reusing buffers | error of C | error of dC/dsigma |\n|---|---|---|---|---|---|---|---|\n"
    );
    for m in results.iter().filter(|m| m.rays == rays && m.samples == samples) {
        if m.method == "fused" && m.threads == 1 {
            continue;
        }
        s += &format!(
            "| {} | {} | {} | {:.0} | {} | {:.0} | {:.1e} | {:.1e} |\n",
            m.method,
            m.precision,
            m.threads,
            m.samples_per_sec / 1e6,
            m.samples_per_sec_one_pass
                .map_or("-".into(), |v| format!("{:.0}", v / 1e6)),
            m.samples_per_sec_reused / 1e6,
            m.err_color,
            m.err_grad_sigma
        );
    }
    s + &format!(
        "\n{} Full report: [reports/bench-composite.md](reports/bench-composite.md).\n",
        stamp.markdown()
    )
}

/// The grid field's headline: every row of the largest grid measured.
pub fn grid_headline(results: &[GridMeasurement], stamp: &Stamp) -> String {
    let Some(grid) = results.iter().map(|m| m.grid).max() else {
        return String::new();
    };
    let mut s = format!(
        "Grid field, {grid}^3 x 4, random lookups, forward + backward into the grid (M lookups/s; errors against a plain f64 loop):\n\n| method | precision | threads | M lookups/s | buffers reused | forward alone | error of output | error of dL/dgrid |\n|---|---|---|---|---|---|---|---|\n"
    );
    for m in results.iter().filter(|m| m.grid == grid) {
        s += &format!(
            "| {} | {} | {} | {:.2} | {:.2} | {:.2} | {:.1e} | {:.1e} |\n",
            m.method,
            m.precision,
            m.threads,
            m.lookups_per_sec / 1e6,
            m.lookups_per_sec_reused / 1e6,
            m.lookups_per_sec_forward / 1e6,
            m.err_output,
            m.err_grad_grid
        );
    }
    s + &format!(
        "\n{} Full report: [reports/bench-grid.md](reports/bench-grid.md).\n",
        stamp.markdown()
    )
}

/// Replaces what stands between `<!-- headline:NAME:start -->` and `<!-- headline:NAME:end -->`
/// in `readme` by `block`. Errors if the markers are missing; the file is then unchanged.
pub fn update_readme(readme: &Path, name: &str, block: &str) -> Result<(), LabError> {
    let text = std::fs::read_to_string(readme).map_err(LabError::file("read", readme))?;
    let (start, end) = (
        format!("<!-- headline:{name}:start -->"),
        format!("<!-- headline:{name}:end -->"),
    );
    let updated = replace_between(&text, &start, &end, block).ok_or_else(|| LabError::MissingMarkers {
        path: readme.display().to_string(),
        start: start.clone(),
        end: end.clone(),
    })?;
    // Whole or not at all: a README is the user's, and a half-written one loses their text.
    Ok(fogray_data::write_atomic(readme, |out| {
        out.write_all(updated.as_bytes())
    })?)
}

fn replace_between(text: &str, start: &str, end: &str, block: &str) -> Option<String> {
    let a = text.find(start)? + start.len();
    let b = a + text[a..].find(end)?;
    Some(format!("{}\n{}\n{}", &text[..a], block.trim_end(), &text[b..]))
}

#[cfg(test)]
mod tests {
    use super::replace_between;

    #[test]
    fn only_the_marked_block_changes() {
        let text = "a\n<!-- s -->\nold\n<!-- e -->\nb\n";
        assert_eq!(
            replace_between(text, "<!-- s -->", "<!-- e -->", "new\n").unwrap(),
            "a\n<!-- s -->\nnew\n<!-- e -->\nb\n"
        );
        assert!(replace_between(text, "<!-- x -->", "<!-- e -->", "new").is_none());
    }
}
