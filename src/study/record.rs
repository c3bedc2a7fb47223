//! One measurement, and the CSV it is appended to as soon as it is measured: an interrupted
//! study keeps every row written before the interruption.

use std::fs::File;
use std::path::{Path, PathBuf};

use super::StudyError;

/// Where a study ran: written into every row, so rows from several runs can be pooled.
#[derive(Clone, Debug)]
pub struct Machine {
    /// UTC, ISO 8601, when the study started.
    pub date: String,
    /// The host name.
    pub host: String,
    /// The CPU's model name.
    pub cpu: String,
    /// Threads rayon runs on.
    pub threads: usize,
}

impl Machine {
    /// This machine, now.
    pub fn this() -> Machine {
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .map(|h| h.trim().to_owned())
            .unwrap_or_else(|_| "unknown".into());
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|info| {
                info.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split_once(':'))
                    .map(|(_, v)| v.trim().to_owned())
            })
            .unwrap_or_else(|| std::env::consts::ARCH.to_owned());
        Machine {
            date: utc_now(),
            host,
            cpu,
            threads: rayon::current_num_threads(),
        }
    }
}

/// The current UTC time as `YYYY-MM-DDTHH:MM:SSZ`.
fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86400), secs.rem_euclid(86400));
    // Howard Hinnant's civil_from_days.
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// The device a row was measured on.
#[derive(Clone, Debug, PartialEq)]
pub struct Device {
    /// cpu, wgpu or ash.
    pub backend: String,
    /// The adapter's name.
    pub adapter: String,
    /// The driver, as the device string names it (empty if it does not).
    pub driver: String,
    /// How its times were taken: device timestamps or the wall clock.
    pub timer: &'static str,
}

impl Device {
    /// From a backend's name and its device string (`name (driver)`, as the backends write it).
    pub fn of(backend: &str, device: &str, timer: &'static str) -> Device {
        // The driver is the last parenthesised part (which may hold parentheses itself).
        let mut depth = 0usize;
        let mut open = None;
        if device.ends_with(')') {
            for (i, c) in device.char_indices().rev() {
                match c {
                    ')' => depth += 1,
                    '(' => {
                        depth = depth.saturating_sub(1);
                        if depth == 0 {
                            open = Some(i);
                            break;
                        }
                    }
                    _ => {}
                }
            }
        }
        let (adapter, driver) = match open {
            Some(i) if i > 0 => (
                device[..i].trim_end().to_owned(),
                device[i + 1..device.len() - 1].to_owned(),
            ),
            _ => (device.to_owned(), String::new()),
        };
        Device {
            backend: backend.to_owned(),
            adapter,
            driver,
            timer,
        }
    }
}

/// One measurement: a metric under one set of settings, with the value of each repetition.
#[derive(Clone, Debug)]
pub struct Row {
    /// The device it ran on.
    pub device: Device,
    /// What distinguishes a line in the plot beside the backend (e.g. `K=16`, `rt pipeline`).
    pub variant: String,
    /// The data set's name.
    pub data: String,
    /// The step measured.
    pub step: usize,
    /// Particles in the step.
    pub n: usize,
    /// The study's settings, in the order of its columns.
    pub settings: Vec<(&'static str, String)>,
    /// What was measured (e.g. `build`), the CSV's metric column.
    pub metric: &'static str,
    /// The metric's unit.
    pub unit: &'static str,
    /// One value per repetition, in the order measured.
    pub values: Vec<f64>,
}

impl Row {
    /// The median of the repetitions.
    pub fn median(&self) -> f64 {
        median(&self.values)
    }

    /// The least repetition.
    pub fn min(&self) -> f64 {
        self.values.iter().copied().fold(f64::INFINITY, f64::min)
    }

    /// The largest repetition.
    pub fn max(&self) -> f64 {
        self.values
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// A setting's value as written.
    pub fn setting(&self, key: &str) -> Option<&str> {
        self.settings
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, v)| v.as_str())
    }

    /// A setting's value as a number (NaN where it has none).
    pub fn number(&self, key: &str) -> f64 {
        self.setting(key)
            .and_then(|v| v.parse().ok())
            .unwrap_or(f64::NAN)
    }

    /// The backend and variant: one line of a plot.
    pub fn series(&self) -> String {
        if self.variant.is_empty() {
            self.device.backend.clone()
        } else {
            format!("{} {}", self.device.backend, self.variant)
        }
    }
}

/// The median (the mean of the middle two for an even count); NaN for none.
pub fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// The columns every study's CSV starts with, before its settings.
pub const LEADING_COLUMNS: [&str; 12] = [
    "date", "machine", "cpu", "threads", "backend", "adapter", "driver", "timer", "variant",
    "data", "step", "n",
];
/// The columns after the settings.
pub const TRAILING_COLUMNS: [&str; 7] = [
    "metric",
    "unit",
    "repetitions",
    "median",
    "min",
    "max",
    "values",
];

/// A study's CSV, a row appended and flushed as each measurement ends, and the rows so far.
pub struct Recorder {
    path: PathBuf,
    writer: csv::Writer<File>,
    machine: Machine,
    settings: Vec<&'static str>,
    rows: Vec<Row>,
}

impl Recorder {
    /// Creates `path` (replacing any file there: the caller checked `--force`) with the header
    /// for a study whose settings are `settings`.
    pub fn create(
        path: &Path,
        machine: Machine,
        settings: &[&'static str],
    ) -> Result<Recorder, StudyError> {
        let io = |e: std::io::Error| StudyError::io(path, e);
        let file = File::create(path).map_err(io)?;
        let mut writer = csv::Writer::from_writer(file);
        let header: Vec<&str> = LEADING_COLUMNS
            .iter()
            .chain(settings)
            .chain(&TRAILING_COLUMNS)
            .copied()
            .collect();
        writer
            .write_record(&header)
            .map_err(|e| StudyError::io(path, e.into()))?;
        writer.flush().map_err(io)?;
        Ok(Recorder {
            path: path.to_owned(),
            writer,
            machine,
            settings: settings.to_vec(),
            rows: Vec::new(),
        })
    }

    /// Where the study ran.
    pub fn machine(&self) -> &Machine {
        &self.machine
    }

    /// The CSV file the rows are appended to.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The settings columns.
    pub fn settings(&self) -> &[&'static str] {
        &self.settings
    }

    /// Appends `row` to the CSV and flushes it. A row whose settings are not the study's
    /// columns, or with no value or a value that is not finite, is refused (a bug, reported as
    /// an error rather than a number in a table).
    pub fn record(&mut self, row: Row) -> Result<(), StudyError> {
        let keys: Vec<&str> = row.settings.iter().map(|(k, _)| *k).collect();
        if keys != self.settings {
            return Err(StudyError::Invalid(format!(
                "a row of {} has settings {keys:?}, the study's columns are {:?}",
                row.metric, self.settings
            )));
        }
        if row.values.is_empty() || row.values.iter().any(|v| !v.is_finite()) {
            return Err(StudyError::Invalid(format!(
                "{} on {} ({}): measured values {:?} are not all finite",
                row.metric,
                row.series(),
                row.data,
                row.values
            )));
        }
        let m = &self.machine;
        let mut record: Vec<String> = vec![
            m.date.clone(),
            m.host.clone(),
            m.cpu.clone(),
            m.threads.to_string(),
            row.device.backend.clone(),
            row.device.adapter.clone(),
            row.device.driver.clone(),
            row.device.timer.to_owned(),
            row.variant.clone(),
            row.data.clone(),
            row.step.to_string(),
            row.n.to_string(),
        ];
        record.extend(row.settings.iter().map(|(_, v)| v.clone()));
        record.extend([
            row.metric.to_owned(),
            row.unit.to_owned(),
            row.values.len().to_string(),
            format!("{}", row.median()),
            format!("{}", row.min()),
            format!("{}", row.max()),
            row.values
                .iter()
                .map(|v| format!("{v}"))
                .collect::<Vec<_>>()
                .join(";"),
        ]);
        self.writer
            .write_record(&record)
            .map_err(|e| StudyError::io(&self.path, e.into()))?;
        self.writer
            .flush()
            .map_err(|e| StudyError::io(&self.path, e))?;
        self.rows.push(row);
        Ok(())
    }

    /// Every row recorded so far, in order.
    pub fn rows(&self) -> &[Row] {
        &self.rows
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_are_utc_iso() {
        let d = utc_now();
        assert_eq!(d.len(), 20, "{d}");
        assert!(d.ends_with('Z') && d.as_bytes()[10] == b'T', "{d}");
    }

    #[test]
    fn medians_and_devices() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&[]).is_nan());
        let d = Device::of(
            "ash",
            "llvmpipe (LLVM 15.0.6, 256 bits) (Mesa 25.0.7 (LLVM 15.0.6))",
            "t",
        );
        assert_eq!(d.adapter, "llvmpipe (LLVM 15.0.6, 256 bits)");
        assert_eq!(d.driver, "Mesa 25.0.7 (LLVM 15.0.6)");
        let d = Device::of("cpu", "CPU, 2 threads", "t");
        assert_eq!(
            (d.adapter.as_str(), d.driver.as_str()),
            ("CPU, 2 threads", "")
        );
    }

    #[test]
    fn rows_are_flushed_as_recorded_and_checked() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.csv");
        let mut r = Recorder::create(&path, Machine::this(), &["k"]).unwrap();
        let row = Row {
            device: Device::of("cpu", "CPU, 2 threads", "wall clock"),
            variant: "K=1".into(),
            data: "uniform".into(),
            step: 0,
            n: 10,
            settings: vec![("k", "1".into())],
            metric: "frame",
            unit: "ms",
            values: vec![1.0, 3.0, 2.0],
        };
        r.record(row.clone()).unwrap();
        // Written before the recorder is dropped.
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text.lines().count(), 2, "{text}");
        assert!(
            text.lines()
                .nth(1)
                .unwrap()
                .ends_with(",frame,ms,3,2,1,3,1;3;2")
        );
        let bad = Row {
            values: vec![f64::NAN],
            ..row.clone()
        };
        assert!(r.record(bad).is_err());
        let wrong = Row {
            settings: vec![("radius", "1".into())],
            ..row
        };
        assert!(r.record(wrong).is_err());
    }
}
