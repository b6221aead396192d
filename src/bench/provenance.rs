//! Where a measurement came from: when, from which commit, on which host (CPU, caches, memory,
//! OS, Mesa and LLVM) and with how many lavapipe threads — what it takes to compare two
//! benchmark files fairly. Lavapipe's speed, and the RBVH's ratio to the exact BVH with it, change
//! with the CPU's caches: the same structure ran at 1.05x the exact BVH on one project machine and
//! 0.44x on another with 16 MB of L3.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

use crate::gpu::Context;

/// Where and when a measurement was taken: what leads every results file (`rbvh bench`'s and
/// `rbvh shaders`'), flattened into it, and the line printed above their tables.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct Provenance {
    /// The Vulkan device's name, as it reports itself.
    pub device: String,
    /// The driver's name and version, as the device reports them.
    pub driver: String,
    /// When the measurement started, UTC, ISO 8601 (`2025-01-31T12:00:00Z`).
    pub date: String,
    /// The commit measured ([`git_commit`]); None outside a repository.
    pub git: Option<String>,
    /// Whether code differed from `git` ([`git_dirty`]); None outside a repository or with
    /// `RBVH_COMMIT`.
    pub git_dirty: Option<bool>,
    /// The machine, with the threads the device's driver ran on.
    pub host: Host,
    /// This crate's version.
    pub version: String,
}

impl Provenance {
    /// A measurement starting now on `ctx`'s device, on this machine, of the current commit.
    pub fn of(ctx: &Context) -> Provenance {
        Provenance {
            device: ctx.device_name().to_string(),
            driver: ctx.driver().to_string(),
            date: utc_now(),
            git: git_commit(),
            git_dirty: git_dirty(),
            host: Host::current(ctx.driver(), lavapipe_threads(ctx)),
            version: env!("CARGO_PKG_VERSION").to_string(),
        }
    }

    /// The commit as tables print it: ten characters, `+ uncommitted changes` where code
    /// differed, `no commit` outside a repository.
    pub fn commit_label(&self) -> String {
        match (&self.git, self.git_dirty) {
            (Some(c), Some(true)) => format!("{} + uncommitted changes", short_commit(c)),
            (Some(c), _) => short_commit(c),
            (None, _) => "no commit".into(),
        }
    }

    /// One line above a run's tables: `host: …; device: … (driver); commit; date`, so that a
    /// copied table says where it was taken.
    pub fn line(&self) -> String {
        format!(
            "host: {}; device: {} ({}); {}; {}",
            self.host.summary(),
            self.device,
            self.driver,
            self.commit_label(),
            self.date
        )
    }
}

/// The current time in UTC as ISO 8601 / RFC 3339 (`YYYY-MM-DDThh:mm:ssZ`).
pub fn utc_now() -> String {
    iso8601(SystemTime::now())
}

/// `time` as ISO 8601 / RFC 3339 in UTC, to the second. A clock outside the years 1970–9999
/// (which humantime refuses to format) reads as the nearer end.
pub fn iso8601(time: SystemTime) -> String {
    let last = UNIX_EPOCH + Duration::from_secs(253_402_300_799); // 9999-12-31T23:59:59Z
    humantime::format_rfc3339_seconds(time.clamp(UNIX_EPOCH, last)).to_string()
}

pub use crate::scene::available_memory;

/// The commit measured: `RBVH_COMMIT` where set (a binary run outside its repository, as on a GPU
/// machine that was handed a copy of the tree), else `git rev-parse HEAD` in the current
/// directory, or None when git or a repository is missing.
pub fn git_commit() -> Option<String> {
    if let Some(commit) = std::env::var("RBVH_COMMIT")
        .ok()
        .filter(|c| !c.trim().is_empty())
    {
        return Some(commit.trim().to_string());
    }
    let out = Command::new("git")
        .args(["rev-parse", "HEAD"])
        .output()
        .ok()?;
    let commit = String::from_utf8(out.stdout).ok()?.trim().to_string();
    (out.status.success() && !commit.is_empty()).then_some(commit)
}

/// The first ten characters of a commit (fewer where it is shorter; any text, since
/// `RBVH_COMMIT` may name it).
fn short_commit(commit: &str) -> String {
    commit.chars().take(10).collect()
}

/// Whether tracked files other than documentation (`docs/`, `*.md`) differ from `HEAD` in the
/// current directory's repository — the measurement is then of uncommitted code; results files
/// and the tables made from them are committed after it — or None when git or a repository is
/// missing.
pub fn git_dirty() -> Option<bool> {
    if std::env::var("RBVH_COMMIT").is_ok_and(|c| !c.trim().is_empty()) {
        return None;
    }
    let out = Command::new("git")
        // Paths from the repository's top, wherever in it the command runs (relative ones
        // would ask only about the current folder: run from `scenes/`, changed code was clean).
        .args([
            "status",
            "--porcelain",
            "--untracked-files=no",
            "--",
            ":(top)",
        ])
        .args([":(top,exclude)docs", ":(top,exclude,glob)**/*.md"])
        .output()
        .ok()?;
    out.status.success().then_some(!out.stdout.is_empty())
}

/// Mesa's `LP_MAX_THREADS` (`lp_limits.h`; 32 in Mesa 22.3, which the project runs on): llvmpipe
/// starts no more worker threads than this, whatever `LP_NUM_THREADS` or the CPU count says.
const LP_MAX_THREADS: u32 = 32;

/// The threads lavapipe (Mesa's llvmpipe) runs compute dispatches on, or None for any other
/// device: counted as Mesa counts its workers (`lavapipe_threads_for`), from `LP_NUM_THREADS` and
/// the CPUs this process may run on.
pub fn lavapipe_threads(ctx: &Context) -> Option<u32> {
    if !ctx.device_name().contains("llvmpipe") {
        return None;
    }
    let cpus = std::thread::available_parallelism()
        .ok()
        .map(|n| u32::try_from(n.get()).unwrap_or(u32::MAX));
    Some(lavapipe_threads_for(
        std::env::var("LP_NUM_THREADS").ok().as_deref(),
        cpus,
    ))
}

/// The threads llvmpipe runs on, as its screen counts its workers when the device is created
/// (`llvmpipe_create_screen`, Mesa 22.3): one a CPU where there are several, `LP_NUM_THREADS`
/// where it is a number, at most [`LP_MAX_THREADS`]; with no worker (one CPU, or
/// `LP_NUM_THREADS=0`) a dispatch runs on the thread that submits it, one thread. `cpus` is what
/// the standard library says this process may use, which a CPU quota (cgroups) may make fewer
/// than the CPUs Mesa counts; `LP_NUM_THREADS` is read as a decimal number, where Mesa's
/// `strtol` also takes hexadecimal and a trailing text.
fn lavapipe_threads_for(lp_num_threads: Option<&str>, cpus: Option<u32>) -> u32 {
    let workers = lp_num_threads
        .and_then(|v| v.trim().parse::<u32>().ok())
        .unwrap_or(cpus.filter(|&n| n > 1).unwrap_or(0));
    workers.clamp(1, LP_MAX_THREADS)
}

/// The machine a measurement ran on: what decides lavapipe's speed (the CPU, its caches, the Mesa
/// and LLVM that compile the shaders for it) and what tells two hosts' numbers apart. Read from
/// Linux's `/proc` and `/sys` ([`Host::current`]); a field the system does not tell is None.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct Host {
    /// The CPU's model name (`/proc/cpuinfo`).
    pub cpu: Option<String>,
    /// Physical cores of the machine (distinct core ids per package in `/proc/cpuinfo`), which a
    /// container or an affinity mask may leave fewer of to this process ([`Host::logical_cpus`]).
    pub cores: Option<u32>,
    /// Logical CPUs this process may run on.
    pub logical_cpus: Option<u32>,
    /// Worker threads the device's driver ran on: lavapipe's ([`lavapipe_threads`]); None for a
    /// GPU.
    pub threads_used: Option<u32>,
    /// Bytes of the level-2 cache the first CPU uses (typically per core).
    pub l2_bytes: Option<u64>,
    /// Bytes of the level-3 cache the first CPU shares (a slice's share is not reported).
    pub l3_bytes: Option<u64>,
    /// Memory of the machine, in bytes (`MemTotal`).
    pub memory_bytes: Option<u64>,
    /// The operating system's name (`/etc/os-release`) and kernel release.
    pub os: Option<String>,
    /// Whether the CPU runs under a hypervisor (the `hypervisor` CPU flag): a guest's caches and
    /// cores may be shared with other guests.
    pub virtualized: Option<bool>,
    /// Mesa's version, for a Mesa driver (lavapipe, RADV), from its driver string.
    pub mesa: Option<String>,
    /// LLVM's version, for a driver that compiles through LLVM (lavapipe), from its driver string.
    pub llvm: Option<String>,
}

impl Host {
    /// This machine, with the Mesa and LLVM versions read from `driver` (a device's driver
    /// string, [`Context::driver`]) and `threads_used` as the run used them.
    pub fn current(driver: &str, threads_used: Option<u32>) -> Host {
        let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
        let meminfo = std::fs::read_to_string("/proc/meminfo").unwrap_or_default();
        let os_release = std::fs::read_to_string("/etc/os-release").unwrap_or_default();
        let kernel = std::fs::read_to_string("/proc/sys/kernel/osrelease").ok();
        let cache =
            |level: u32| cache_bytes(Path::new("/sys/devices/system/cpu/cpu0/cache"), level);
        let (mesa, llvm) = driver_versions(driver);
        Host {
            cpu: cpu_field(&cpuinfo, "model name")
                .map(|m| m.split_whitespace().collect::<Vec<_>>().join(" ")),
            cores: physical_cores(&cpuinfo),
            logical_cpus: std::thread::available_parallelism()
                .ok()
                .map(|n| n.get() as u32),
            threads_used,
            l2_bytes: cache(2),
            l3_bytes: cache(3),
            memory_bytes: meminfo
                .lines()
                .find_map(|l| l.strip_prefix("MemTotal:"))
                .and_then(|v| v.trim().strip_suffix("kB"))
                .and_then(|kb| kb.trim().parse::<u64>().ok())
                .map(|kb| kb * 1024),
            os: os_name(&os_release, kernel.as_deref()),
            virtualized: cpu_field(&cpuinfo, "flags")
                .map(|flags| flags.split_whitespace().any(|f| f == "hypervisor")),
            mesa,
            llvm,
        }
    }

    /// One line for people: `Intel Xeon …, 2 cores (2 threads used), L2 2 MiB, L3 480 MiB,
    /// 23.4 GiB memory, Debian GNU/Linux 12 (bookworm), kernel …, virtual machine, Mesa 22.3.6,
    /// LLVM 15.0.6`; what is unknown is left out.
    pub fn summary(&self) -> String {
        let mut parts = vec![self.cpu.clone().unwrap_or_else(|| "CPU not known".into())];
        let mut cores = match (self.cores, self.logical_cpus) {
            (Some(c), Some(l)) if l != c => format!("{c} cores, {l} logical CPUs"),
            (Some(c), _) => format!("{c} cores"),
            (None, Some(l)) => format!("{l} logical CPUs"),
            (None, None) => String::new(),
        };
        if let Some(t) = self.threads_used {
            cores = format!("{cores} ({t} threads used)").trim().to_string();
        }
        parts.push(cores);
        parts.extend(self.l2_bytes.map(|b| format!("L2 {}", binary_size(b))));
        parts.extend(self.l3_bytes.map(|b| format!("L3 {}", binary_size(b))));
        parts.extend(
            self.memory_bytes
                .map(|b| format!("{} memory", binary_size(b))),
        );
        parts.extend(self.os.clone());
        if self.virtualized == Some(true) {
            parts.push("virtual machine".into());
        }
        parts.extend(self.mesa.as_ref().map(|v| format!("Mesa {v}")));
        parts.extend(self.llvm.as_ref().map(|v| format!("LLVM {v}")));
        parts.retain(|p| !p.is_empty());
        parts.join(", ")
    }
}

/// `bytes` in the largest binary unit that keeps a whole number or one decimal: `480 MiB`,
/// `1.5 MiB`, `23.4 GiB`.
pub fn binary_size(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    if value.fract() == 0.0 {
        format!("{value:.0} {}", UNITS[unit])
    } else {
        format!("{value:.1} {}", UNITS[unit])
    }
}

/// The first value of `key` in `/proc/cpuinfo`'s text.
fn cpu_field<'a>(cpuinfo: &'a str, key: &str) -> Option<&'a str> {
    cpuinfo.lines().find_map(|line| {
        let (k, v) = line.split_once(':')?;
        (k.trim() == key)
            .then(|| v.trim())
            .filter(|v| !v.is_empty())
    })
}

/// Distinct (physical id, core id) pairs of `/proc/cpuinfo`; None where it lists no core ids
/// (some architectures and containers).
fn physical_cores(cpuinfo: &str) -> Option<u32> {
    let mut cores = std::collections::BTreeSet::new();
    let (mut package, mut core) = (None, None);
    for line in cpuinfo.lines().chain(std::iter::once("")) {
        if line.trim().is_empty() {
            if let Some(c) = core.take() {
                cores.insert((package.take().unwrap_or(""), c));
            }
            package = None;
            continue;
        }
        if let Some((k, v)) = line.split_once(':') {
            match k.trim() {
                "physical id" => package = Some(v.trim()),
                "core id" => core = Some(v.trim()),
                _ => {}
            }
        }
    }
    (!cores.is_empty()).then_some(cores.len() as u32)
}

/// Bytes of the unified or data cache of `level` under a CPU's `cache` folder of sysfs
/// (`index*/level`, `type`, `size` as `2048K`).
fn cache_bytes(cache: &Path, level: u32) -> Option<u64> {
    let read = |dir: &Path, name: &str| std::fs::read_to_string(dir.join(name)).ok();
    std::fs::read_dir(cache).ok()?.flatten().find_map(|entry| {
        let dir = entry.path();
        let at_level = read(&dir, "level")?.trim().parse::<u32>().ok()? == level;
        let kind = read(&dir, "type")?;
        if !at_level || kind.trim() == "Instruction" {
            return None;
        }
        parse_size(read(&dir, "size")?.trim())
    })
}

/// A sysfs cache size: `48K`, `2048K`, `480M`, or plain bytes.
fn parse_size(text: &str) -> Option<u64> {
    let (digits, scale) = match text.chars().last()? {
        'K' => (&text[..text.len() - 1], 1 << 10),
        'M' => (&text[..text.len() - 1], 1 << 20),
        'G' => (&text[..text.len() - 1], 1 << 30),
        _ => (text, 1),
    };
    digits.parse::<u64>().ok().map(|n| n * scale)
}

/// `PRETTY_NAME` of `/etc/os-release`, with the kernel release: `Debian GNU/Linux 12 (bookworm),
/// kernel 6.1.0`.
fn os_name(os_release: &str, kernel: Option<&str>) -> Option<String> {
    let name = os_release
        .lines()
        .find_map(|l| l.strip_prefix("PRETTY_NAME="))
        .map(|v| v.trim().trim_matches('"').to_string());
    let kernel = kernel.map(|k| format!("kernel {}", k.trim()));
    match (name, kernel) {
        (Some(n), Some(k)) => Some(format!("{n}, {k}")),
        (n, k) => n.or(k),
    }
}

/// The Mesa and LLVM versions in a driver string: `llvmpipe Mesa 22.3.6 (LLVM 15.0.6) (Vulkan
/// 1.3.230)` gives (`22.3.6`, `15.0.6`); a non-Mesa driver gives neither.
pub fn driver_versions(driver: &str) -> (Option<String>, Option<String>) {
    let after = |word: &str| {
        let words: Vec<&str> = driver
            .split(|c: char| c.is_whitespace() || c == '(' || c == ')')
            .filter(|w| !w.is_empty())
            .collect();
        words
            .windows(2)
            .find(|w| w[0] == word && w[1].starts_with(|c: char| c.is_ascii_digit()))
            .map(|w| w[1].to_string())
    };
    (after("Mesa"), after("LLVM"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_instants() {
        let at = |secs| iso8601(UNIX_EPOCH + Duration::from_secs(secs));
        assert_eq!(at(0), "1970-01-01T00:00:00Z");
        assert_eq!(at(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(at(1_709_251_199), "2024-02-29T23:59:59Z");
        assert_eq!(at(4_102_444_800), "2100-01-01T00:00:00Z");
        assert_eq!(
            iso8601(UNIX_EPOCH - Duration::from_secs(5)),
            "1970-01-01T00:00:00Z"
        );
        assert_eq!(at(u64::MAX / 4), "9999-12-31T23:59:59Z");
    }

    #[test]
    fn mesa_and_llvm_come_from_the_driver_string() {
        assert_eq!(
            driver_versions("llvmpipe Mesa 22.3.6 (LLVM 15.0.6) (Vulkan 1.3.230)"),
            (Some("22.3.6".into()), Some("15.0.6".into()))
        );
        assert_eq!(
            driver_versions("radv Mesa 22.3.6 (Vulkan 1.3.230)"),
            (Some("22.3.6".into()), None)
        );
        assert_eq!(
            driver_versions("NVIDIA 570.86.15 (Vulkan 1.4.303)"),
            (None, None)
        );
    }

    #[test]
    fn cpuinfo_caches_and_os() {
        let cpuinfo =
            "processor\t: 0\nmodel name\t: Intel(R)  Xeon(R) Processor\nphysical id\t: 0\n\
                       core id\t\t: 0\nflags\t\t: fpu hypervisor avx2\n\n\
                       processor\t: 1\nphysical id\t: 0\ncore id\t\t: 0\n\n\
                       processor\t: 2\nphysical id\t: 0\ncore id\t\t: 1\n";
        assert_eq!(
            cpu_field(cpuinfo, "model name"),
            Some("Intel(R)  Xeon(R) Processor")
        );
        assert_eq!(physical_cores(cpuinfo), Some(2));
        assert_eq!(physical_cores("processor : 0\n"), None);
        assert_eq!(parse_size("2048K"), Some(2 << 20));
        assert_eq!(parse_size("480M"), Some(480 << 20));
        assert_eq!(parse_size("512"), Some(512));
        assert_eq!(parse_size("x"), None);
        assert_eq!(binary_size(480 << 20), "480 MiB");
        assert_eq!(binary_size(3 << 19), "1.5 MiB");
        assert_eq!(
            os_name(
                "NAME=x\nPRETTY_NAME=\"Debian GNU/Linux 12 (bookworm)\"\n",
                Some("6.1.0\n")
            ),
            Some("Debian GNU/Linux 12 (bookworm), kernel 6.1.0".into())
        );
        assert_eq!(os_name("", None), None);
    }

    #[test]
    fn a_commit_is_labelled_by_characters_and_its_state() {
        let mut p = Provenance {
            git: Some("d45624a2b54996ca2d0136b2352f1b820a7dc957".into()),
            git_dirty: Some(true),
            ..Provenance::default()
        };
        assert_eq!(p.commit_label(), "d45624a2b5 + uncommitted changes");
        p.git = Some("été".into());
        p.git_dirty = None;
        assert_eq!(p.commit_label(), "été");
        p.git = None;
        assert_eq!(p.commit_label(), "no commit");
    }

    #[test]
    fn a_summary_leaves_out_what_is_unknown() {
        let host = Host {
            cpu: Some("AMD EPYC".into()),
            cores: Some(2),
            logical_cpus: Some(2),
            threads_used: Some(2),
            l3_bytes: Some(16 << 20),
            virtualized: Some(true),
            mesa: Some("22.3.6".into()),
            ..Host::default()
        };
        assert_eq!(
            host.summary(),
            "AMD EPYC, 2 cores (2 threads used), L3 16 MiB, virtual machine, Mesa 22.3.6"
        );
        assert_eq!(Host::default().summary(), "CPU not known");
    }

    #[test]
    fn lavapipe_threads_are_counted_as_mesa_counts_its_workers() {
        use super::lavapipe_threads_for as threads;
        assert_eq!(threads(None, Some(2)), 2);
        assert_eq!(threads(None, Some(1)), 1);
        assert_eq!(threads(None, None), 1);
        assert_eq!(threads(None, Some(128)), 32);
        assert_eq!(threads(Some("4"), Some(2)), 4);
        assert_eq!(threads(Some(" 8 "), Some(2)), 8);
        assert_eq!(threads(Some("0"), Some(16)), 1);
        assert_eq!(threads(Some("64"), Some(2)), 32);
        assert_eq!(threads(Some("many"), Some(6)), 6);
    }
}
