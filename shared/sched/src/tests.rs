//! The settings checked as the config reads them, and applied to real threads: what the
//! kernel then reports for the thread (`/proc/self/task/<tid>/status`) is what was asked.

use super::*;

/// `Cpus_allowed_list` of the calling thread, as the kernel reports it.
fn cpus_allowed_list() -> String {
    let tid = rustix::thread::gettid().as_raw_nonzero();
    let path = format!("/proc/self/task/{tid}/status");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    text.lines()
        .find_map(|l| l.strip_prefix("Cpus_allowed_list:"))
        .unwrap_or_else(|| panic!("no Cpus_allowed_list in {path}"))
        .trim()
        .to_string()
}

fn settings(toml_text: &str) -> SchedSettings {
    toml::from_str(toml_text).unwrap_or_else(|e| panic!("{toml_text}: {e}"))
}

fn refusal(toml_text: &str) -> String {
    match settings(toml_text).validate("stages.matcher") {
        Ok(()) => panic!("accepted: {toml_text}"),
        Err(e) => e,
    }
}

#[test]
fn bad_values_are_named_with_what_is_allowed() {
    for (toml_text, expected) in [
        ("cpus = []", "stages.matcher.cpus = []"),
        (
            "cpus = [0, 5000]",
            "stages.matcher.cpus: CPU 5000 is out of range",
        ),
        (
            "policy = \"fifo\"",
            "stages.matcher.priority: policy fifo needs a priority",
        ),
        (
            "policy = \"rr\"\npriority = 0",
            "stages.matcher.priority = 0 is out of range",
        ),
        (
            "policy = \"fifo\"\npriority = 100",
            "stages.matcher.priority = 100 is out of range",
        ),
        (
            "priority = 10",
            "stages.matcher.priority = 10: a priority applies to policy",
        ),
        (
            "policy = \"other\"\npriority = 3",
            "applies to policy \"fifo\" or \"rr\"",
        ),
        (
            "nice = 20",
            "stages.matcher.nice = 20 is out of range: allowed -20 ..= 19",
        ),
        ("nice = -21", "stages.matcher.nice = -21 is out of range"),
        (
            "policy = \"fifo\"\npriority = 5\nnice = 1",
            "nice applies to policy \"other\"",
        ),
    ] {
        let err = refusal(toml_text);
        assert!(err.contains(expected), "{toml_text}: {err}");
    }
    // Unknown keys and policies are the parser's to refuse, naming them.
    let unknown = toml::from_str::<SchedSettings>("cpu = [1]")
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(unknown.contains("cpu"), "{unknown}");
    let unknown = toml::from_str::<SchedSettings>("policy = \"deadline\"")
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(unknown.contains("deadline"), "{unknown}");
}

#[test]
fn the_ends_of_every_range_are_accepted() {
    for toml_text in [
        "",
        "cpus = [0, 1023]",
        "policy = \"fifo\"\npriority = 1",
        "policy = \"rr\"\npriority = 99",
        "policy = \"other\"\nnice = -20",
        "nice = 19",
    ] {
        if let Err(e) = settings(toml_text).validate("stages.matcher") {
            panic!("{toml_text}: {e}");
        }
    }
}

#[test]
fn a_thread_pinned_to_cpu_0_runs_on_cpu_0_only_and_its_creator_is_untouched() {
    let before = cpus_allowed_list();
    let pinned = std::thread::spawn(|| {
        let refused = apply(
            "line-detector",
            &SchedSettings {
                cpus: Some(vec![0]),
                ..SchedSettings::default()
            },
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(refused.is_empty(), "{refused:?}");
        // A thread it starts inherits the pinning (OpenCV's pool, iceoryx2's threads).
        let child = std::thread::spawn(cpus_allowed_list)
            .join()
            .unwrap_or_else(|_| panic!("child thread"));
        (cpus_allowed_list(), child)
    })
    .join()
    .unwrap_or_else(|_| panic!("pinned thread"));
    assert_eq!(pinned, ("0".to_string(), "0".to_string()));
    assert_eq!(cpus_allowed_list(), before);
}

#[test]
fn a_cpu_that_does_not_exist_is_an_error_naming_stage_and_cpu() {
    let err = probe(
        "matcher",
        &SchedSettings {
            cpus: Some(vec![0, 1023]),
            ..SchedSettings::default()
        },
    )
    .err()
    .map(|e| e.to_string())
    .unwrap_or_default();
    assert!(
        err.contains("stages.matcher.cpus: CPU 1023 is not available here")
            && err.contains("may run on CPUs 0"),
        "{err}"
    );
}

#[test]
fn a_raised_nice_value_is_applied_to_the_thread() {
    let nice = std::thread::spawn(|| {
        let refused = apply("pose-estimator", &settings("policy = \"other\"\nnice = 7"))
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(refused.is_empty(), "{refused:?}");
        rustix::process::getpriority_process(None).unwrap_or_else(|e| panic!("{e}"))
    })
    .join()
    .unwrap_or_else(|_| panic!("thread"));
    assert_eq!(nice, 7);
}

#[test]
fn a_real_time_policy_is_applied_or_refused_by_name() {
    // Priority 1 on a thread that only reads its policy back and ends: harmless to the
    // machine either way. With the privilege (root, CAP_SYS_NICE, RLIMIT_RTPRIO) it is
    // applied; without it the refusal names the stage, the setting and what grants it.
    let (refused, policy) = std::thread::spawn(|| {
        let refused = apply("matcher", &settings("policy = \"fifo\"\npriority = 1"))
            .unwrap_or_else(|e| panic!("{e}"));
        let policy = policy::of_this_thread().unwrap_or_else(|e| panic!("{e}"));
        (
            refused.iter().map(ToString::to_string).collect::<Vec<_>>(),
            policy,
        )
    })
    .join()
    .unwrap_or_else(|_| panic!("thread"));
    if refused.is_empty() {
        assert_eq!(policy, libc::SCHED_FIFO);
    } else {
        assert_eq!(policy, libc::SCHED_OTHER);
        assert!(
            refused[0].contains("stages.matcher.policy = fifo, priority 1 not permitted")
                && refused[0].contains("LimitRTPRIO"),
            "{refused:?}"
        );
    }
}

#[test]
fn cpu_lists_read_like_the_kernels() {
    let mut set = rustix::thread::CpuSet::new();
    for cpu in [0, 1, 2, 5, 7, 8] {
        set.set(cpu);
    }
    assert_eq!(cpu_list(&set), "0-2, 5, 7-8");
}
