//! The memory this process may still take beside what the machine has free: an address-space
//! limit (`ulimit -v`, `RLIMIT_AS`) less the address space already mapped, and a control
//! group's memory limit less what the group holds that the kernel cannot drop. Past either, an
//! allocation fails (the process aborts, or the group's OOM killer ends it) however much memory
//! the machine has free, so [`available`](super::available) takes the smallest.
//!
//! Everything is read from `/proc` and `/sys/fs/cgroup` as text (the same figures `getrlimit`
//! and the cgroup files give), and each reading is a pure function of that text, tested on
//! literal files.

use super::Bytes;

/// A limit at or above this is "no limit" (cgroup v1 writes its unlimited as the largest
/// page-aligned `i64`, about 9.2e18).
const UNLIMITED: u64 = 1 << 62;

/// The soft `Max address space` of a `/proc/self/limits` text, in bytes; `None` if unlimited or
/// not given.
pub fn address_space_limit(limits: &str) -> Option<Bytes> {
    let line = limits.lines().find(|l| l.starts_with("Max address space"))?;
    let soft = line["Max address space".len()..].split_whitespace().next()?;
    soft.parse::<u64>().ok().filter(|&b| b < UNLIMITED).map(Bytes)
}

/// The `VmSize:` of a `/proc/self/status` text (the address space mapped, what `RLIMIT_AS`
/// counts), in bytes.
pub fn mapped(status: &str) -> Option<Bytes> {
    let line = status.lines().find(|l| l.starts_with("VmSize:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(Bytes(kib.saturating_mul(1024)))
}

/// `limit - mapped`: what a process under an address-space `limit` may still map; `None`
/// without a limit.
pub fn address_space_headroom(limits: &str, status: &str) -> Option<Bytes> {
    let limit = address_space_limit(limits)?;
    let used = mapped(status).unwrap_or_default();
    Some(Bytes(limit.0.saturating_sub(used.0)))
}

/// A control group's memory files: its limit (`memory.max`, or v1's
/// `memory.limit_in_bytes`), its usage (`memory.current`, or `memory.usage_in_bytes`) and its
/// `memory.stat`.
#[derive(Debug, Clone, Copy)]
pub struct CgroupFiles<'a> {
    /// The limit's text: bytes, or `max` (unlimited).
    pub limit: &'a str,
    /// The usage's text, in bytes.
    pub usage: &'a str,
    /// The `memory.stat` text.
    pub stat: &'a str,
}

/// What a group under `files` may still take: its limit less its usage, the page cache it
/// holds (`file` in cgroup v2's `memory.stat`, `total_cache` in v1's) counted as free, since
/// the kernel drops it before it fails an allocation; `None` without a limit.
pub fn cgroup_headroom(files: CgroupFiles<'_>) -> Option<Bytes> {
    let limit: u64 = files.limit.trim().parse().ok().filter(|&b| b < UNLIMITED)?;
    let usage: u64 = files.usage.trim().parse().unwrap_or(0);
    let cache = files
        .stat
        .lines()
        .find_map(|l| match l.split_once(' ') {
            Some(("file" | "total_cache", v)) => v.trim().parse::<u64>().ok(),
            _ => None,
        })
        .unwrap_or(0);
    Some(Bytes(limit.saturating_sub(usage.saturating_sub(cache))))
}

/// The folders whose memory limits apply to a process whose `/proc/self/cgroup` is `cgroups`:
/// its group's in the v2 hierarchy (the line `0::/path`) and in v1's memory hierarchy (a line
/// `N:memory:/path`), each with its ancestors up to the mount point (a parent's limit binds
/// its children too), as `(folder, v2)`.
pub fn cgroup_folders(cgroups: &str) -> Vec<(String, bool)> {
    let mut folders = Vec::new();
    for line in cgroups.lines() {
        let mut fields = line.splitn(3, ':');
        let (Some(_), Some(controllers), Some(path)) = (fields.next(), fields.next(), fields.next()) else {
            continue;
        };
        let (root, v2) = match controllers {
            "" => ("/sys/fs/cgroup", true),
            c if c.split(',').any(|c| c == "memory") => ("/sys/fs/cgroup/memory", false),
            _ => continue,
        };
        let mut path = path.trim_end_matches('/');
        loop {
            folders.push((format!("{root}{path}"), v2));
            match path.rfind('/') {
                Some(cut) => path = &path[..cut],
                None => break,
            }
        }
    }
    folders
}

/// The least headroom of this process: under its address-space limit and under each control
/// group limit that applies to it; `None` where none is set or the system does not say.
pub fn process_headroom() -> Option<Bytes> {
    let read = |path: &str| std::fs::read_to_string(path).ok();
    let address_space = match (read("/proc/self/limits"), read("/proc/self/status")) {
        (Some(limits), Some(status)) => address_space_headroom(&limits, &status),
        _ => None,
    };
    let groups = read("/proc/self/cgroup")
        .map(|c| cgroup_folders(&c))
        .unwrap_or_default();
    let cgroups = groups.iter().filter_map(|(folder, v2)| {
        let [limit, usage] = if *v2 {
            ["memory.max", "memory.current"]
        } else {
            ["memory.limit_in_bytes", "memory.usage_in_bytes"]
        };
        let limit = read(&format!("{folder}/{limit}"))?;
        let usage = read(&format!("{folder}/{usage}")).unwrap_or_default();
        let stat = read(&format!("{folder}/memory.stat")).unwrap_or_default();
        cgroup_headroom(CgroupFiles {
            limit: &limit,
            usage: &usage,
            stat: &stat,
        })
    });
    address_space.into_iter().chain(cgroups).min()
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: &str = "Limit                     Soft Limit           Hard Limit           Units     \n\
        Max stack size            8388608              unlimited            bytes     \n\
        Max address space         4096000000           8192000000           bytes     \n";

    #[test]
    fn an_address_space_limit_less_what_is_mapped_is_the_headroom() {
        // `ulimit -v 4000000` (KiB) is 4 096 000 000 bytes; 100 000 KiB mapped leaves
        // 4 096 000 000 - 102 400 000.
        assert_eq!(address_space_limit(LIMITS), Some(Bytes(4_096_000_000)));
        let status = "Name:\tfogray\nVmPeak:\t  200000 kB\nVmSize:\t  100000 kB\n";
        assert_eq!(mapped(status), Some(Bytes(102_400_000)));
        assert_eq!(address_space_headroom(LIMITS, status), Some(Bytes(3_993_600_000)));
        // More mapped than the limit (a limit lowered after the fact): nothing left.
        assert_eq!(address_space_headroom(LIMITS, "VmSize:\t 5000000 kB\n"), Some(Bytes(0)));
        let unlimited = "Max address space         unlimited            unlimited            bytes     \n";
        assert_eq!(address_space_headroom(unlimited, status), None);
    }

    #[test]
    fn a_cgroup_counts_its_page_cache_as_free() {
        // v2: 1 GiB limit, 600 MB used of which 200 MB page cache: 1073741824 - 400000000.
        let v2 = CgroupFiles {
            limit: "1073741824\n",
            usage: "600000000\n",
            stat: "anon 390000000\nfile 200000000\nkernel 10000000\n",
        };
        assert_eq!(cgroup_headroom(v2), Some(Bytes(673_741_824)));
        assert_eq!(cgroup_headroom(CgroupFiles { limit: "max\n", ..v2 }), None);
        // v1: the cache is `total_cache` (`cache` is the group's own, without its children).
        let v1 = CgroupFiles {
            limit: "2000000000\n",
            usage: "1500000000\n",
            stat: "cache 1000\nrss 5000\ntotal_cache 700000000\ntotal_rss 800000000\n",
        };
        assert_eq!(cgroup_headroom(v1), Some(Bytes(1_200_000_000)));
        // v1's unlimited: the largest page-aligned i64.
        let unlimited = CgroupFiles {
            limit: "9223372036854771712\n",
            ..v1
        };
        assert_eq!(cgroup_headroom(unlimited), None);
    }

    #[test]
    fn the_groups_that_bind_are_the_process_s_and_its_ancestors() {
        let text = "4:memory:/api/job7\n3:cpu,cpuacct:/\n0::/user.slice/s1\n";
        assert_eq!(
            cgroup_folders(text),
            vec![
                ("/sys/fs/cgroup/memory/api/job7".to_string(), false),
                ("/sys/fs/cgroup/memory/api".to_string(), false),
                ("/sys/fs/cgroup/memory".to_string(), false),
                ("/sys/fs/cgroup/user.slice/s1".to_string(), true),
                ("/sys/fs/cgroup/user.slice".to_string(), true),
                ("/sys/fs/cgroup".to_string(), true),
            ]
        );
        // The root group (a container's own namespace): the mount point alone.
        assert_eq!(cgroup_folders("0::/\n"), vec![("/sys/fs/cgroup".to_string(), true)]);
    }
}
