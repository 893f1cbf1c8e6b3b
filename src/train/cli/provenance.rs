//! Where a result came from, as model cards and result files record it: the exact command line,
//! the machine (cores and CPU model) and the git commit of the source tree.

/// The command line of this process, its arguments joined by spaces.
pub fn command_line() -> String {
    std::env::args().collect::<Vec<_>>().join(" ")
}

/// `<cores> cores, <CPU model>` (the CPU from `/proc/cpuinfo`, else `unknown CPU`).
pub fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| cpu_model(&t))
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    format!("{cores} cores, {cpu}")
}

/// The first `model name` of a `/proc/cpuinfo` text.
fn cpu_model(cpuinfo: &str) -> Option<String> {
    cpuinfo
        .lines()
        .find(|l| l.starts_with("model name"))
        .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
}

/// The short hash of the checked-out commit (`git rev-parse --short HEAD` in the working
/// directory), or `None` outside a repository or without git.
pub fn git_commit() -> Option<String> {
    let out = std::process::Command::new("git")
        .args(["rev-parse", "--short", "HEAD"])
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_model_reads_the_first_model_name() {
        let text = "processor\t: 0\nmodel name\t: Example CPU @ 2.00GHz\nflags\t: x\n\
                    processor\t: 1\nmodel name\t: Other\n";
        assert_eq!(cpu_model(text).as_deref(), Some("Example CPU @ 2.00GHz"));
        assert_eq!(cpu_model("processor\t: 0\n"), None);
        let m = machine();
        let (cores, cpu) = m.split_once(" cores, ").expect(&m);
        assert!(
            cores.parse::<usize>().unwrap() >= 1 && !cpu.is_empty(),
            "{m}"
        );
    }
}
