//! `fogray-lab`: the lab's measurements from the command line (`fogray-lab bench`), with the
//! reports and README blocks they generate. Not part of the `fogray` command a user runs: it
//! counts every allocation (for each method's peak extra memory), which only a measurement
//! should pay for.

use std::alloc::System;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};
use peakmem_alloc::{PeakMemAlloc, PeakMemAllocTrait, INSTRUMENTED_SYSTEM};

use fogray_lab::error::LabError;
use fogray_lab::{bench, grid_bench, heap, markdown, tape_cost};

/// Counts allocated bytes, so that `fogray-lab bench` can report each method's peak extra
/// memory. (A counter that forwards `alloc_zeroed` and `realloc` to the system allocator: one
/// that zeroes with `memset` touches every page up front and distorts the timings it sits
/// under.)
#[global_allocator]
static PEAK: &PeakMemAlloc<System> = &INSTRUMENTED_SYSTEM;

struct Allocator;

/// Which op `fogray-lab bench` measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum BenchOp {
    /// The emission-absorption composite and its taped twins.
    Composite,
    /// The trilinear grid field and its taped twin.
    Grid,
}

impl bench::Memory for Allocator {
    fn reset(&self) {
        PEAK.reset_peak_memory();
    }
    fn peak_since_reset(&self) -> usize {
        PEAK.get_peak_memory()
    }
}

#[derive(Parser)]
#[command(
    name = "fogray-lab",
    version,
    about = "fogray's measurements: speed beside error and memory, written as reports"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Samples per second (forward+backward with the spread of the runs, and forward alone) of
    /// the fused op on 1 and all threads and of the stable and naive taped twins (all threads:
    /// the tape's element-wise ops run on rayon's pool), also in a
    /// training loop's steady state ("reused": the fused op into output and gradient buffers
    /// kept across runs, the twins on one tape cleared between runs) and, for the fused op, in
    /// one pass per ray ("1-pass": `evaluate_vjp_into`, the same bits), in f32 and f64, on the
    /// workloads 4096x64, 65536x64, 16384x256 and 1024x4096 (RGB; sigma ~ U[0,5], total
    /// optical depth ~5), each beside its error against an independent compensated f64
    /// reference on the same rays and its peak extra memory; then the tape's own cost per
    /// recorded op and per byte. A short STREAM triad after the workloads measures the bytes per
    /// second the machine streams (1 thread and all; its arrays larger than the largest cache);
    /// each fused row shows its two-call (`reused`) and one-pass speeds as the fraction of that
    /// bound they reach for the bytes they must move per sample.
    ///
    /// With --op grid: lookups per second of the fused trilinear grid field (1 thread and all)
    /// and of its taped twin (all threads, a quarter of the lookups), forward + backward into the
    /// grid and forward alone, 4,194,304 lookups at uniform random positions in 128^3 x 4 and
    /// 64^3 x 4 grids, f32 and f64, each beside its error against a plain f64 loop on the same
    /// lookups and its peak extra memory.
    Bench {
        /// Which op to measure.
        #[arg(long, value_enum, default_value = "composite")]
        op: BenchOp,
        /// A single run per measurement, without warm-up, instead of the median of at least five
        /// runs (and at least 0.3 s of them) after a warm-up run.
        #[arg(long)]
        quick: bool,
        /// Print {"bandwidth": [...], "results": [...], "tape_overhead": [...]} as JSON
        /// (composite; the grid field prints {"results": [...]}).
        #[arg(long)]
        json: bool,
        /// Only this workload, as RxS (rays x samples per ray) for the composite, or N (an N^3 x 4
        /// grid) for the grid field.
        #[arg(long)]
        workload: Option<String>,
        /// Have glibc keep freed memory for reuse (a training loop's steady state) instead of
        /// returning it, so that the main thread's buffers are not fresh pages (the fused
        /// 1-thread runs allocate on a pool thread, which this does not cover). Linux with
        /// glibc only.
        #[arg(long)]
        keep_freed_memory: bool,
        /// Also write the report as markdown into this directory (bench-composite.md or
        /// bench-grid.md), stamped with the date, the machine and the command.
        #[arg(long)]
        markdown: Option<PathBuf>,
        /// With --markdown: also put the headline rows into this README, between its
        /// <!-- headline:composite:start/end --> (or grid) markers.
        #[arg(long, requires = "markdown")]
        readme: Option<PathBuf>,
    },
}

/// Where `fogray-lab bench` writes its generated report, if anywhere.
struct Publish<'a> {
    dir: Option<&'a std::path::Path>,
    readme: Option<&'a std::path::Path>,
    command: String,
}

impl Publish<'_> {
    /// Writes `DIR/bench-NAME.md` and the README's headline block.
    fn write(
        &self,
        name: &str,
        title: &str,
        tables: &str,
        headline: impl Fn(&fogray_lab::stamp::Stamp) -> String,
    ) -> Result<(), LabError> {
        let Some(dir) = self.dir else { return Ok(()) };
        let stamp = fogray_lab::stamp::Stamp::now(&self.command);
        std::fs::create_dir_all(dir).map_err(LabError::file("create", dir))?;
        let path = dir.join(format!("bench-{name}.md"));
        let report = markdown::report(title, &stamp, tables);
        fogray_data::write_atomic(&path, |out| out.write_all(report.as_bytes()))?;
        match self.readme {
            Some(readme) => markdown::update_readme(readme, name, &headline(&stamp)),
            None => Ok(()),
        }
    }
}

fn bench_grid(quick: bool, json: bool, workload: Option<&str>, publish: &Publish) -> Result<String, LabError> {
    let grids = match workload {
        Some(w) => vec![w.parse::<usize>().ok().filter(|&n| n >= 2).ok_or_else(|| {
            LabError::Option(format!(
                "grid workload {w:?} is not a node count of at least 2 (for example 128)"
            ))
        })?],
        None => grid_bench::GRIDS.to_vec(),
    };
    let mut log = |m: &grid_bench::GridMeasurement| {
        if !json {
            eprintln!(
                "  grid {} {} {} thread(s) {}^3x{}: {:.2} M lookups/s",
                m.method,
                m.precision,
                m.threads,
                m.grid,
                m.channels,
                m.lookups_per_sec / 1e6
            );
        }
    };
    let results = grid_bench::run(&grids, quick, &Allocator, &mut log)?;
    publish.write(
        "grid",
        "The grid field: lookups per second and errors",
        &grid_bench::table(&results),
        |s| markdown::grid_headline(&results, s),
    )?;
    if json {
        Ok(serde_json::to_string_pretty(
            &serde_json::json!({ "results": results }),
        )?)
    } else {
        Ok(grid_bench::table(&results))
    }
}

fn bench_composite(quick: bool, json: bool, workload: Option<&str>, publish: &Publish) -> Result<String, LabError> {
    let workloads = match workload {
        Some(w) => vec![bench::parse_workload(w)?],
        None => bench::WORKLOADS.to_vec(),
    };
    let mut log = |m: &bench::Measurement| {
        if !json {
            eprintln!(
                "  {} {} {} thread(s) {}x{}: {:.1} M samples/s",
                m.method,
                m.precision,
                m.threads,
                m.rays,
                m.samples,
                m.samples_per_sec / 1e6
            );
        }
    };
    let mut results = bench::run(&workloads, quick, &Allocator, &mut log)?;
    let bandwidth = bench::bandwidths(quick)?;
    bench::attach_bounds(&mut results, &bandwidth);
    let tape = tape_cost::run(quick)?;
    let tables = bench::bandwidth_table(&bandwidth) + &bench::table(&results) + &tape_cost::table(&tape);
    publish.write(
        "composite",
        "The composite: samples per second and errors",
        &tables,
        |s| markdown::composite_headline(&results, s),
    )?;
    if json {
        Ok(serde_json::to_string_pretty(
            &serde_json::json!({ "bandwidth": bandwidth, "results": results, "tape_overhead": tape }),
        )?)
    } else {
        Ok(tables)
    }
}

/// The report's destination and the command line that asked for it (for the stamp).
fn publish<'a>(markdown: &'a Option<PathBuf>, readme: &'a Option<PathBuf>) -> Publish<'a> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    Publish {
        dir: markdown.as_deref(),
        readme: readme.as_deref(),
        command: format!("fogray-lab {}", args.join(" ")),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let (name, result) = match &cli.command {
        Command::Bench {
            op,
            quick,
            json,
            workload,
            keep_freed_memory,
            markdown,
            readme,
        } => (
            "bench",
            if *keep_freed_memory {
                heap::keep_freed_memory()
            } else {
                Ok(())
            }
            .and_then(|()| match op {
                BenchOp::Composite => bench_composite(*quick, *json, workload.as_deref(), &publish(markdown, readme)),
                BenchOp::Grid => bench_grid(*quick, *json, workload.as_deref(), &publish(markdown, readme)),
            }),
        ),
    };
    match result {
        Ok(out) => {
            println!("{out}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            // One line: the reason, with any newline of a nested message folded and the control
            // characters of a name read from a file escaped.
            let message = e.to_string().replace('\n', " ");
            eprintln!("fogray-lab {name}: error: {}", fogray_data::escape_controls(&message));
            ExitCode::from(2)
        }
    }
}
