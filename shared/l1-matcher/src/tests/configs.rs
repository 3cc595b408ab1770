//! The shipped configuration files, and bad ones named by their culprit.

use super::*;

fn config_path(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../configs")
        .join(name)
}

#[test]
fn shipped_config_files_say_what_the_code_does() {
    assert_eq!(
        MatcherConfig::from_file(&config_path("l1-matcher.toml")).unwrap(),
        MatcherConfig::default()
    );
    assert_eq!(
        MatcherConfig::from_file(&config_path("l1-matcher-paper.toml")).unwrap(),
        MatcherConfig::paper()
    );
}

#[test]
fn bad_configs_name_the_culprit() {
    let unknown = MatcherConfig::from_toml_str("lambda = 0.1\nlamda = 0.2\n")
        .unwrap_err()
        .to_string();
    assert!(unknown.contains("lamda"), "{unknown}");
    let nan = MatcherConfig::from_toml_str("lambda = nan")
        .unwrap_err()
        .to_string();
    assert!(nan.contains("`lambda`"), "{nan}");
    let typed = MatcherConfig::from_toml_str("[gates]\nmax_angle_deg = \"ten\"")
        .unwrap_err()
        .to_string();
    assert!(
        typed.contains("max_angle_deg") && typed.contains("line 2"),
        "{typed}"
    );
    let range = MatcherConfig::from_toml_str("[gates]\nmin_overlap = 1.5")
        .unwrap_err()
        .to_string();
    assert!(range.contains("gates.min_overlap"), "{range}");
    let missing = MatcherConfig::from_file(std::path::Path::new("/nonexistent/matcher.toml"))
        .unwrap_err()
        .to_string();
    assert!(missing.contains("/nonexistent/matcher.toml"), "{missing}");
    assert!(
        L1Matcher::new(MatcherConfig {
            error_ratio: 0.5,
            ..Default::default()
        })
        .is_err()
    );
    for (text, field) in [
        ("[stereo]\nerror_ratio = 0.9", "stereo.error_ratio"),
        (
            "[gates]\nstereo_min_overlap = -0.1",
            "gates.stereo_min_overlap",
        ),
        (
            "[photometric]\nmin_correlation = 1.5",
            "photometric.min_correlation",
        ),
        ("[photometric]\nweight = inf", "photometric.weight"),
        (
            "[predicted]\nmax_displacement_px = -1.0",
            "predicted.max_displacement_px",
        ),
        (
            "[photometric]\nmax_offset_px = 0.0",
            "photometric.max_offset_px",
        ),
        ("[photometric]\nmin_rows = 0", "photometric.min_rows"),
        (
            "[consistency]\nmin_neighbours = 9",
            "consistency.min_neighbours",
        ),
        (
            "[consistency]\nmax_difference_px = nan",
            "consistency.max_difference_px",
        ),
    ] {
        let error = MatcherConfig::from_toml_str(text).unwrap_err().to_string();
        assert!(error.contains(field), "{text}: {error}");
    }
}
