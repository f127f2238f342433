//! Where a generated measurement comes from: the date, the machine and the command, written at
//! the top of every report so that a figure can always be traced to its run.

use std::time::{SystemTime, UNIX_EPOCH};

/// The provenance of one measurement run.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Stamp {
    /// The UTC date of the run, `YYYY-MM-DD`.
    pub date: String,
    /// The processor's model name and the number of logical processors the OS reports.
    pub machine: String,
    /// Threads in rayon's global pool during the run.
    pub threads: usize,
    /// The command that wrote the report.
    pub command: String,
}

impl Stamp {
    /// The stamp of a run started now by `command`.
    pub fn now(command: &str) -> Self {
        let days = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_secs() / 86_400);
        Stamp {
            date: civil_date(days as i64),
            machine: machine(),
            threads: rayon::current_num_threads(),
            command: command.to_string(),
        }
    }

    /// One markdown paragraph: "Measured on DATE by `COMMAND` on MACHINE (N threads)."
    pub fn markdown(&self) -> String {
        format!(
            "Measured on {} by `{}` on {} ({} threads).",
            self.date, self.command, self.machine, self.threads
        )
    }
}

/// The processor model (from `/proc/cpuinfo` where there is one) and the logical processors.
fn machine() -> String {
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|info| {
            info.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string());
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    format!("{model}, {cpus} logical processors")
}

/// The proleptic Gregorian date of a day count since 1970-01-01 (Howard Hinnant's
/// `civil_from_days`).
fn civil_date(days: i64) -> String {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}")
}

#[cfg(test)]
mod tests {
    use super::civil_date;

    #[test]
    fn civil_dates_of_known_days() {
        assert_eq!(civil_date(0), "1970-01-01");
        // Day counts from Python: (datetime.date(y, m, d) - datetime.date(1970, 1, 1)).days.
        assert_eq!(civil_date(11_017), "2000-03-01");
        assert_eq!(civil_date(19_782), "2024-02-29");
        assert_eq!(civil_date(20_780), "2026-11-23");
        assert_eq!(civil_date(-1), "1969-12-31");
    }
}
