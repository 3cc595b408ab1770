//! Middlebury stereo: the real scenes (`real_data_*`) and hand-made folders, good and
//! malformed.

use super::*;

#[test]
fn real_data_middlebury_scenes_are_selected_by_name_and_an_unknown_one_is_named() {
    let dir = linetrack_test_data::middlebury_dir().unwrap();
    let names = ["Venus".to_string(), "Cones".to_string()];
    let pairs = linetrack_datasets::select_middlebury(&dir, &names).unwrap();
    let found: Vec<&str> = pairs.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(found, ["Cones", "Venus"]);
    assert_eq!(
        linetrack_datasets::select_middlebury(&dir, &[])
            .unwrap()
            .len(),
        28
    );
    let error = linetrack_datasets::select_middlebury(&dir, &["Atlantis".to_string()])
        .unwrap_err()
        .to_string();
    assert!(error.contains("\"Atlantis\""), "{error}");
    assert!(error.contains(dir.to_str().unwrap()), "{error}");
}

#[test]
fn real_data_middlebury_lists_every_pair_with_its_disparity_scale() {
    let dir = linetrack_test_data::middlebury_dir().unwrap();
    let pairs = linetrack_datasets::list_middlebury(&dir).unwrap();
    assert_eq!(pairs.len(), 28);
    let scale = |name: &str| pairs.iter().find(|p| p.name == name).unwrap().scale;
    assert_eq!(
        (
            scale("Tsukuba"),
            scale("Venus"),
            scale("Cones"),
            scale("Baby1")
        ),
        (16.0, 8.0, 4.0, 3.0)
    );
    let tsukuba = pairs
        .iter()
        .find(|p| p.name == "Tsukuba")
        .unwrap()
        .load()
        .unwrap();
    assert_eq!((tsukuba.left.width(), tsukuba.left.height()), (384, 288));
    assert_eq!(
        (tsukuba.disparity.width(), tsukuba.disparity.height()),
        (384, 288)
    );
    // Tsukuba's disparities are 5–14 px; the centre of the lamp is in the front.
    let known: Vec<f64> = (0..288)
        .flat_map(|y| (0..384).map(move |x| (x, y)))
        .filter_map(|(x, y)| tsukuba.disparity.at(f64::from(x), f64::from(y)))
        .collect();
    let (low, high) = known
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &d| (a.min(d), b.max(d)));
    assert!(
        (4.0..=6.0).contains(&low) && (13.0..=15.0).contains(&high),
        "{low} {high}"
    );
    assert!(tsukuba.disparity.coverage() > 0.75);
}

/// A third-size 2005/2006 scene folder with a disparity map `disp1.png` of `map_size`.
fn middlebury_fixture(name: &str, map_size: (u32, u32)) -> Scratch {
    let dir = Scratch::new("datasets", name);
    let scene = dir.join("Scene");
    let colour = image::RgbImage::from_fn(420, 30, |x, y| image::Rgb([x as u8, y as u8, 9]));
    std::fs::create_dir_all(&scene).unwrap();
    colour.save(scene.join("view1.png")).unwrap();
    colour.save(scene.join("view5.png")).unwrap();
    let map = image::GrayImage::from_fn(map_size.0, map_size.1, |x, _| {
        image::Luma([(x % 4) as u8 * 30])
    });
    map.save(scene.join("disp1.png")).unwrap();
    dir
}

#[test]
fn a_middlebury_fixture_loads_grey_with_unknown_disparities() {
    let dir = middlebury_fixture("middlebury-good", (420, 30));
    let pairs = linetrack_datasets::list_middlebury(&dir).unwrap();
    assert_eq!(pairs.len(), 1);
    let pair = pairs[0].load().unwrap();
    assert_eq!((pair.left.width(), pair.left.height()), (420, 30));
    // Value 0 (x % 4 == 0) is unknown, not d = 0; 30 / 3 = 10 px.
    assert_eq!(pair.disparity.at(0.0, 0.0), None);
    assert_eq!(pair.disparity.at(1.0, 0.0), Some(10.0));
    assert_eq!(pair.disparity.at(2.0, 5.0), Some(20.0));
}

#[test]
fn malformed_middlebury_folders_are_refused_naming_the_file() {
    let wrong_size = middlebury_fixture("middlebury-size", (400, 30));
    let error = linetrack_datasets::list_middlebury(&wrong_size).unwrap()[0]
        .load()
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("disp1.png") && error.contains("400×30"),
        "{error}"
    );

    let corrupt = middlebury_fixture("middlebury-corrupt", (420, 30));
    std::fs::write(corrupt.join("Scene/disp1.png"), b"\x89PNG not really").unwrap();
    let error = linetrack_datasets::list_middlebury(&corrupt).unwrap()[0]
        .load()
        .unwrap_err()
        .to_string();
    assert!(error.contains("disp1.png"), "{error}");

    let empty = Scratch::new("datasets", "middlebury-empty");
    let error = linetrack_datasets::list_middlebury(&empty)
        .unwrap_err()
        .to_string();
    assert!(error.contains("no Middlebury pair"), "{error}");
    let missing = linetrack_datasets::list_middlebury(Path::new("/nonexistent/middlebury"))
        .unwrap_err()
        .to_string();
    assert!(missing.contains("/nonexistent/middlebury"), "{missing}");
}
