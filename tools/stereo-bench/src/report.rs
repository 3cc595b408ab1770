//! Aggregates, the goals, and the report (Markdown table, CSV, plot).

use crate::{Condition, PairRow};
use std::fmt::Write as _;
use std::path::Path;

/// The sums over all pairs of one condition × detector × matcher.
#[derive(Debug, Clone, PartialEq)]
pub struct Aggregate {
    /// Condition.
    pub condition: Condition,
    /// Detector name.
    pub detector: &'static str,
    /// Matcher label.
    pub matcher: String,
    /// Pairs summed.
    pub pairs: usize,
    /// Matches.
    pub matches: usize,
    /// Correct matches.
    pub correct: usize,
    /// Judged wrong.
    pub wrong: usize,
    /// Not judged.
    pub unjudged: usize,
    /// Matchable left segments.
    pub matchable: usize,
    /// Left segments detected.
    pub left_segments: usize,
    /// Median milliseconds of description + matching per pair.
    pub median_ms: f64,
}

impl Aggregate {
    /// Correct over judged matches (1 when nothing was judged).
    pub fn precision(&self) -> f64 {
        let judged = self.correct + self.wrong;
        if judged == 0 {
            1.0
        } else {
            self.correct as f64 / judged as f64
        }
    }

    /// The detector's stereo repeatability: matchable left segments (found again in the
    /// right image at the ground-truth disparity, within 1 px and overlapping) over all left
    /// segments (0 when there are none). The same for every matcher.
    pub fn repeatability(&self) -> f64 {
        if self.left_segments == 0 {
            0.0
        } else {
            self.matchable as f64 / self.left_segments as f64
        }
    }

    /// Correct matches over matchable left segments (0 when none is matchable).
    pub fn recall(&self) -> f64 {
        if self.matchable == 0 {
            0.0
        } else {
            self.correct as f64 / self.matchable as f64
        }
    }
}

/// Sums `rows` per condition × detector × matcher, in first-seen order.
pub fn aggregate(rows: &[PairRow]) -> Vec<Aggregate> {
    let mut out: Vec<Aggregate> = Vec::new();
    let mut times: Vec<Vec<f64>> = Vec::new();
    for row in rows {
        let k = match out.iter().position(|a| {
            a.condition == row.condition && a.detector == row.detector && a.matcher == row.matcher
        }) {
            Some(k) => k,
            None => {
                out.push(Aggregate {
                    condition: row.condition,
                    detector: row.detector,
                    matcher: row.matcher.clone(),
                    pairs: 0,
                    matches: 0,
                    correct: 0,
                    wrong: 0,
                    unjudged: 0,
                    matchable: 0,
                    left_segments: 0,
                    median_ms: 0.0,
                });
                times.push(Vec::new());
                out.len() - 1
            }
        };
        let a = &mut out[k];
        a.pairs += 1;
        a.matches += row.matches;
        a.correct += row.correct;
        a.wrong += row.wrong;
        a.unjudged += row.unjudged;
        a.matchable += row.matchable;
        a.left_segments += row.left_segments;
        times[k].push(row.match_ms);
    }
    for (a, t) in out.iter_mut().zip(&mut times) {
        t.sort_by(f64::total_cmp);
        a.median_ms = t.get(t.len() / 2).copied().unwrap_or(0.0);
    }
    out
}

/// One of the acceptance goals for the geometric matcher, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct Goal {
    /// Detector.
    pub detector: &'static str,
    /// Condition.
    pub condition: Condition,
    /// What is asked.
    pub rule: String,
    /// Whether the figures meet it.
    pub met: bool,
    /// The figures.
    pub detail: String,
}

/// Precision the geometric matcher must reach as photographed.
pub const PRECISION_ONE_LIGHT: f64 = 0.95;
/// Precision it must keep under every simulated change.
pub const PRECISION_CHANGED: f64 = 0.90;
/// Factor over LBD's correct matches it must reach on over-exposed images.
pub const OVER_EXPOSED_FACTOR: f64 = 2.0;

/// The goals of `ours` against `baseline` (matcher labels), per detector and condition:
/// as photographed, precision ≥ 0.95 and at least the baseline's correct matches; under
/// every change, at least the baseline's correct matches at precision ≥ 0.90; over-exposed,
/// also at least twice the baseline's correct matches.
pub fn goals(aggregates: &[Aggregate], ours: &str, baseline: &str) -> Vec<Goal> {
    let find = |c: Condition, d: &str, m: &str| {
        aggregates
            .iter()
            .find(|a| a.condition == c && a.detector == d && a.matcher == m)
    };
    let mut goals = Vec::new();
    for a in aggregates.iter().filter(|a| a.matcher == ours) {
        let Some(b) = find(a.condition, a.detector, baseline) else {
            continue;
        };
        let detail = format!(
            "{ours} {} correct at precision {:.3}; {baseline} {} at {:.3}",
            a.correct,
            a.precision(),
            b.correct,
            b.precision()
        );
        let mut push = |rule: String, met: bool| {
            goals.push(Goal {
                detector: a.detector,
                condition: a.condition,
                rule,
                met,
                detail: detail.clone(),
            })
        };
        if a.condition == Condition::AsIs {
            push(
                format!("precision ≥ {PRECISION_ONE_LIGHT} and correct ≥ {baseline}'s"),
                a.precision() >= PRECISION_ONE_LIGHT && a.correct >= b.correct,
            );
            continue;
        }
        push(
            format!("correct ≥ {baseline}'s at precision ≥ {PRECISION_CHANGED}"),
            a.precision() >= PRECISION_CHANGED && a.correct >= b.correct,
        );
        if a.condition == Condition::OverExposed {
            push(
                format!("correct ≥ {OVER_EXPOSED_FACTOR}× {baseline}'s"),
                a.correct as f64 >= OVER_EXPOSED_FACTOR * b.correct as f64,
            );
        }
    }
    goals
}

/// The aggregate table (one row per condition, one column per detector + matcher:
/// correct / precision / recall), the goals, and the matching time.
pub fn markdown(aggregates: &[Aggregate], goals: &[Goal], pairs: usize) -> String {
    let mut columns: Vec<(&'static str, &str)> = Vec::new();
    let mut conditions: Vec<Condition> = Vec::new();
    for a in aggregates {
        if !columns.contains(&(a.detector, a.matcher.as_str())) {
            columns.push((a.detector, a.matcher.as_str()));
        }
        if !conditions.contains(&a.condition) {
            conditions.push(a.condition);
        }
    }
    let mut out = String::new();
    let header: Vec<String> = columns
        .iter()
        .map(|(d, m)| format!("{}+{m}", d.to_uppercase()))
        .collect();
    let _ = writeln!(
        out,
        "Correct matches / precision / recall of the matchable segments, summed over {pairs} pairs.\n"
    );
    let _ = writeln!(out, "| condition | {} |", header.join(" | "));
    let _ = writeln!(out, "|---|{}", "---|".repeat(columns.len()));
    for c in &conditions {
        let cells: Vec<String> = columns
            .iter()
            .map(|(d, m)| {
                aggregates
                    .iter()
                    .find(|a| a.condition == *c && a.detector == *d && a.matcher == *m)
                    .map_or("–".to_string(), |a| {
                        format!("{} / {:.3} / {:.2}", a.correct, a.precision(), a.recall())
                    })
            })
            .collect();
        let _ = writeln!(out, "| {} | {} |", c.name(), cells.join(" | "));
    }
    let mut detectors: Vec<&'static str> = Vec::new();
    for (d, _) in &columns {
        if !detectors.contains(d) {
            detectors.push(d);
        }
    }
    let _ = writeln!(
        out,
        "\nStereo repeatability of the detectors: left segments found again in the right image \
         at the ground-truth disparity (within 1 px of a right segment's line, overlapping it) / \
         left segments, summed over {pairs} pairs:\n"
    );
    let upper: Vec<String> = detectors.iter().map(|d| d.to_uppercase()).collect();
    let _ = writeln!(out, "| condition | {} |", upper.join(" | "));
    let _ = writeln!(out, "|---|{}", "---|".repeat(detectors.len()));
    for c in &conditions {
        let cells: Vec<String> = detectors
            .iter()
            .map(|d| {
                aggregates
                    .iter()
                    .find(|a| a.condition == *c && a.detector == *d)
                    .map_or("–".to_string(), |a| {
                        format!(
                            "{:.3} ({} / {})",
                            a.repeatability(),
                            a.matchable,
                            a.left_segments
                        )
                    })
            })
            .collect();
        let _ = writeln!(out, "| {} | {} |", c.name(), cells.join(" | "));
    }
    let _ = writeln!(
        out,
        "\nMatches returned (correct + wrong + unjudged) and median ms per pair (description of both images + matching):\n"
    );
    let _ = writeln!(out, "| condition | {} |", header.join(" | "));
    let _ = writeln!(out, "|---|{}", "---|".repeat(columns.len()));
    for c in &conditions {
        let cells: Vec<String> = columns
            .iter()
            .map(|(d, m)| {
                aggregates
                    .iter()
                    .find(|a| a.condition == *c && a.detector == *d && a.matcher == *m)
                    .map_or("–".to_string(), |a| {
                        format!(
                            "{} ({} unjudged), {:.2} ms",
                            a.matches, a.unjudged, a.median_ms
                        )
                    })
            })
            .collect();
        let _ = writeln!(out, "| {} | {} |", c.name(), cells.join(" | "));
    }
    if !goals.is_empty() {
        let _ = writeln!(out, "\nGoals of the geometric matcher:\n");
        for g in goals {
            let _ = writeln!(
                out,
                "- {} {} {}: {} — {}",
                if g.met { "✅" } else { "❌" },
                g.detector.to_uppercase(),
                g.condition.name(),
                g.rule,
                g.detail
            );
        }
    }
    let _ = writeln!(out, "\nConditions (applied to the right image only):\n");
    for c in &conditions {
        let _ = writeln!(out, "- `{}`: {}", c.name(), c.description());
    }
    out
}

/// One CSV row per pair × condition × detector × matcher.
pub fn write_csv(path: &Path, rows: &[PairRow]) -> anyhow::Result<()> {
    let mut writer = csv::Writer::from_path(path)?;
    for row in rows {
        writer.serialize(row)?;
    }
    writer.flush()?;
    Ok(())
}

/// Precision against correct matches, one point per condition, one series per
/// detector + matcher.
pub fn plot(path: &Path, aggregates: &[Aggregate]) -> anyhow::Result<()> {
    let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for a in aggregates {
        let name = format!("{}+{}", a.detector.to_uppercase(), a.matcher);
        let point = (a.correct as f64, a.precision());
        match series.iter_mut().find(|(n, _)| *n == name) {
            Some((_, points)) => points.push(point),
            None => series.push((name, vec![point])),
        }
    }
    linetrack_plot::scatter(
        path,
        "Middlebury stereo: precision against correct matches (one point per condition)",
        "correct matches",
        "precision",
        &series,
    )?;
    Ok(())
}
