//! What a benchmark's figures depend on outside raypack: the CPU and its ISA flags, the memory,
//! and how busy the machine was (load average, CPU time of other processes, steal time). Read
//! from Linux's `/proc`; elsewhere the fields are empty and nothing is flagged busy.

use std::time::Duration;

/// The CPU and memory of this machine.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Machine {
    /// The CPU's model name (`/proc/cpuinfo`), or `unknown`.
    pub cpu: String,
    /// The ISA extensions relevant to raypack's and Embree's kernels that this CPU has, in
    /// Rust's `is_x86_feature_detected!` spelling (`sse4.2`, `avx2`, `avx512f`, ...).
    pub cpu_flags: Vec<&'static str>,
    /// Logical CPUs this process may run on.
    pub logical_cpus: usize,
    /// Installed memory in bytes (`MemTotal`).
    pub memory_bytes: Option<u64>,
}

/// The ISA extensions [`Machine::cpu_flags`] reports, in order.
#[cfg(target_arch = "x86_64")]
fn isa_flags() -> Vec<&'static str> {
    let mut v = Vec::new();
    macro_rules! flags {
        ($($f:tt),*) => { $( if std::arch::is_x86_feature_detected!($f) { v.push($f); } )* };
    }
    flags!(
        "sse2", "sse4.1", "sse4.2", "popcnt", "avx", "avx2", "fma", "bmi2", "avx512f", "avx512cd", "avx512dq",
        "avx512bw", "avx512vl"
    );
    v
}

#[cfg(not(target_arch = "x86_64"))]
fn isa_flags() -> Vec<&'static str> {
    Vec::new()
}

/// This machine's CPU, ISA flags, logical CPUs and memory.
pub fn machine() -> Machine {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let cpu = cpuinfo
        .lines()
        .find_map(|l| l.strip_prefix("model name").and_then(|r| r.split_once(':')).map(|(_, v)| v.trim().to_string()))
        .unwrap_or_else(|| "unknown".into());
    let memory_bytes = std::fs::read_to_string("/proc/meminfo").ok().and_then(|m| {
        let kib: u64 =
            m.lines().find_map(|l| l.strip_prefix("MemTotal:"))?.trim().strip_suffix("kB")?.trim().parse().ok()?;
        Some(kib * 1024)
    });
    Machine {
        cpu,
        cpu_flags: isa_flags(),
        logical_cpus: std::thread::available_parallelism().map_or(1, |n| n.get()),
        memory_bytes,
    }
}

/// The 1-, 5- and 15-minute load averages (`/proc/loadavg`).
pub fn load_average() -> Option<[f64; 3]> {
    parse_loadavg(&std::fs::read_to_string("/proc/loadavg").ok()?)
}

fn parse_loadavg(text: &str) -> Option<[f64; 3]> {
    let mut it = text.split_whitespace().map(|f| f.parse::<f64>().ok());
    Some([it.next()??, it.next()??, it.next()??])
}

/// The machine's CPU time so far, in clock ticks (the `cpu` line of `/proc/stat`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CpuTimes {
    /// All ticks (user, nice, system, idle, iowait, irq, softirq, steal).
    pub total: u64,
    /// Idle and iowait ticks.
    pub idle: u64,
    /// Ticks the hypervisor gave to other guests while this one wanted to run.
    pub steal: u64,
    /// Ticks this process ran, all its threads (`/proc/self/stat`'s utime and stime).
    pub own: u64,
}

impl CpuTimes {
    /// Now, or `None` where `/proc/stat` cannot be read.
    pub fn now() -> Option<Self> {
        let own = std::fs::read_to_string("/proc/self/stat").ok().and_then(|t| parse_self_stat(&t)).unwrap_or(0);
        Some(CpuTimes { own, ..parse_stat(&std::fs::read_to_string("/proc/stat").ok()?)? })
    }

    /// Fractions of the CPU time from `earlier` to `self` that was busy (not idle) and stolen.
    pub fn since(&self, earlier: &CpuTimes) -> (f64, f64) {
        let total = self.total.saturating_sub(earlier.total).max(1) as f64;
        let idle = self.idle.saturating_sub(earlier.idle) as f64;
        let steal = self.steal.saturating_sub(earlier.steal) as f64;
        ((1.0 - idle / total).clamp(0.0, 1.0), (steal / total).clamp(0.0, 1.0))
    }

    /// The share of all CPU time from `earlier` to `self` that other processes kept busy:
    /// the busy ticks less this process's own.
    pub fn others_since(&self, earlier: &CpuTimes) -> f64 {
        let total = self.total.saturating_sub(earlier.total).max(1) as f64;
        let busy = (self.total - self.idle).saturating_sub(earlier.total - earlier.idle);
        let own = self.own.saturating_sub(earlier.own);
        (busy.saturating_sub(own) as f64 / total).clamp(0.0, 1.0)
    }
}

/// utime + stime from `/proc/self/stat` (fields 14 and 15; the command name in field 2 may
/// hold spaces, so fields are counted after its closing parenthesis).
fn parse_self_stat(text: &str) -> Option<u64> {
    let rest = &text[text.rfind(')')? + 1..];
    let mut f = rest.split_whitespace().skip(11);
    Some(f.next()?.parse::<u64>().ok()? + f.next()?.parse::<u64>().ok()?)
}

fn parse_stat(text: &str) -> Option<CpuTimes> {
    let line = text.lines().find(|l| l.starts_with("cpu "))?;
    let f: Vec<u64> = line.split_whitespace().skip(1).take(8).map(|x| x.parse().ok()).collect::<Option<_>>()?;
    let at = |i: usize| f.get(i).copied().unwrap_or(0);
    Some(CpuTimes { total: f.iter().sum(), idle: at(3) + at(4), steal: at(7), own: 0 })
}

/// The share of all CPUs that other processes kept busy over `window` (this process sleeps
/// meanwhile), or `None` without `/proc/stat`.
pub fn busy_fraction(window: Duration) -> Option<f64> {
    let a = CpuTimes::now()?;
    std::thread::sleep(window);
    Some(CpuTimes::now()?.since(&a).0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_loadavg_and_stat() {
        assert_eq!(parse_loadavg("0.52 0.31 0.20 1/234 5678\n"), Some([0.52, 0.31, 0.20]));
        assert_eq!(parse_loadavg("garbage"), None);
        let a = parse_stat("cpu  100 0 50 800 50 0 0 0 0 0\ncpu0 1 2 3\n").unwrap();
        let b = parse_stat("cpu  200 0 50 850 50 0 0 50 0 0\n").unwrap();
        assert_eq!(a, CpuTimes { total: 1000, idle: 850, steal: 0, own: 0 });
        // 200 ticks passed: 50 idle, 50 stolen.
        assert_eq!(b.since(&a), (0.75, 0.25));
        // 150 busy ticks, 100 of them this process's: others kept 50 of 200 busy.
        let (a, b) = (CpuTimes { own: 10, ..a }, CpuTimes { own: 110, ..b });
        assert_eq!(b.others_since(&a), 0.25);
        let stat = "1234 (a (b) c) S 1 1 1 0 -1 4194304 100 0 0 0 37 5 0 0 20 0 3 0 100 0 0";
        assert_eq!(parse_self_stat(stat), Some(42));
    }
}
