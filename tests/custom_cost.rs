//! The README's extension example (`examples/custom_cost.rs`) builds, runs, and its cost
//! moves the camera toward the preferred height.

#[allow(dead_code)]
#[path = "../examples/custom_cost.rs"]
mod custom_cost;

#[test]
fn custom_height_cost_moves_the_camera_toward_its_height() {
    let without = custom_cost::mean_height("").unwrap();
    let with = custom_cost::mean_height(custom_cost::WITH_HEIGHT).unwrap();
    let preferred = 2.0;
    assert!(
        (with - preferred).abs() < (without - preferred).abs() - 0.05,
        "mean height without the cost {without:.3}, with it {with:.3}, preferred {preferred}"
    );
}

#[test]
fn an_unregistered_custom_cost_is_an_error_naming_it() {
    let text = format!(
        "{}\n[costs.custom.nope]\nweight = 1.0\n",
        custom_cost::CONFIG
    );
    let err = splatraj::experiment::Config::from_toml(
        &text,
        std::path::Path::new("."),
        &custom_cost::extensions(),
    )
    .unwrap_err();
    let message = format!("{err:#}");
    assert!(message.contains("costs.custom.nope"), "{message}");
    assert!(
        message.contains("height"),
        "lists the registered costs: {message}"
    );
}
