use super::*;

/// The text of every `<text>` element of an SVG document.
fn texts(svg: &str) -> Vec<String> {
    svg.split("<text")
        .skip(1)
        .map(|t| t[t.find('>').unwrap() + 1..t.find("</text>").unwrap()].trim().to_string())
        .collect()
}

#[test]
fn a_log_axis_labels_its_whole_range_once_per_tick() {
    // A spectrum from 156 Hz to 5 kHz: labels below the first full decade too.
    let (bold, light) = log_ticks(156.0 / 1.1, 5000.0 * 1.1);
    assert_eq!(bold, [200.0, 300.0, 500.0, 700.0, 1000.0, 2000.0, 3000.0, 5000.0]);
    assert!(light.len() > bold.len() && light.windows(2).all(|w| w[0] < w[1]), "{light:?}");
    // Three decades: 1-2-5; many: the decades only; each tick once (no second 10).
    assert_eq!(log_ticks(9.0, 5500.0).0, [10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0, 2000.0, 5000.0]);
    assert_eq!(log_ticks(0.9, 11.0).0, [1.0, 2.0, 3.0, 5.0, 7.0, 10.0]);
    assert_eq!(log_ticks(1e-3, 1e9).0, [1e-3, 1e-1, 1e1, 1e3, 1e5, 1e7, 1e9]);
    let labels: Vec<String> = [0.3, 0.02, 200.0, 5000.0].map(|k| log_label(&k)).to_vec();
    assert_eq!(labels, ["0.3", "0.02", "200", "5000"]);
    let f = |k: f64| (k, -20.0 - k / 100.0);
    let chart = Chart {
        title: "spectrum".into(),
        x_label: "frequency [Hz]".into(),
        y_label: "PSD".into(),
        series: vec![Series {
            label: "r".into(),
            points: (156..5000).step_by(13).map(|k| f(k as f64)).collect(),
            color: 0,
        }],
        y_range: None,
    };
    let t = texts(&svg_panels(&[chart], (800, 500), XScale::Log).unwrap());
    for label in ["200", "500", "1000", "5000"] {
        assert_eq!(t.iter().filter(|s| *s == label).count(), 1, "{label} in {t:?}");
    }
}

#[test]
fn linear_tick_labels_are_distinct_and_never_negative_zero() {
    let labels = |r: std::ops::Range<f64>| {
        let f = linear_format(&r);
        RangedCoordf64::from(r).key_points(LABELS).iter().map(|&v| f(&v)).collect::<Vec<_>>()
    };
    // A coherence of 0.99996–1: each tick its own label (not all `1.0`).
    let c = labels(0.999_958..1.000_002);
    assert!(c.len() >= 4 && c.windows(2).all(|w| w[0] != w[1]), "{c:?}");
    // Ticks from −0.4: the one at 0 reads 0.0, not −0.0.
    let r = labels(-0.46..1.04);
    assert!(
        r.contains(&"0.0".to_string())
            && !r.iter().any(|s| s.starts_with('-') && s.parse::<f64>() == Ok(0.0)),
        "{r:?}"
    );
    assert_eq!(linear_format(&(-0.46..1.04))(&-1e-17), "0.0");
    assert_eq!(labels(-180.0..-20.0)[0], "-180.0");
}

/// The legend box (x0, y0, x1, y1) of each panel and the polylines of the curves (1 px wide;
/// axes and ticks are black, curves in the palette's other colours or its near-black).
type LegendBox = (f64, f64, f64, f64);
type Curve = Vec<(f64, f64)>;

fn legends_and_curves(svg: &str) -> (Vec<LegendBox>, Vec<Curve>) {
    let attr = |e: &str, name: &str| -> f64 {
        let at = e.find(&format!(" {name}=\"")).unwrap() + name.len() + 3;
        e[at..].split('"').next().unwrap().parse().unwrap()
    };
    let boxes = svg
        .split("<rect")
        .skip(1)
        .map(|r| r.split('>').next().unwrap())
        .filter(|r| r.contains("stroke=\"#C8C8C8\""))
        .map(|r| {
            let (x, y) = (attr(r, "x"), attr(r, "y"));
            (x, y, x + attr(r, "width"), y + attr(r, "height"))
        })
        .collect();
    let curves = svg
        .split("<polyline")
        .skip(1)
        .map(|l| l.split('>').next().unwrap())
        .filter(|l| l.contains("stroke-width=\"1\"") && !l.contains("stroke=\"#000000\""))
        .map(|l| {
            let pts = l.split("points=\"").nth(1).unwrap().split('"').next().unwrap();
            pts.split_whitespace()
                .map(|p| {
                    let (x, y) = p.split_once(',').unwrap();
                    (x.parse().unwrap(), y.parse().unwrap())
                })
                .collect()
        })
        .collect();
    (boxes, curves)
}

#[test]
fn the_legend_covers_no_curve() {
    let series = |label: &str, points: Vec<(f64, f64)>, color| Series { label: label.into(), points, color };
    let chart = |title: &str, series: Vec<Series>, y_range| Chart {
        title: title.into(),
        x_label: "x".into(),
        y_label: "y".into(),
        series,
        y_range,
    };
    // Ten cycles of a sine over the whole width (a time series), a straight line from the
    // upper left through where the legend sat (a Bode plot over two bins), a coherence at 1
    // on its fixed 0–1 axis.
    let sine =
        |phase: f64| (0..500).map(move |k| (k as f64, (0.13 * k as f64 + phase).sin())).collect::<Vec<_>>();
    let cases = [
        vec![chart(
            "time",
            vec![series("measured", sine(0.0), 0), series("model ja+mech", sine(0.1), 1)],
            None,
        )],
        vec![
            chart("gain", vec![series("measured", vec![(156.0, -33.6), (312.0, -34.3)], 0)], None),
            chart("", vec![series("measured", vec![(156.0, 0.99), (312.0, 0.995)], 2)], Some((0.0, 1.0))),
        ],
    ];
    for charts in cases {
        let svg = svg_panels(&charts, (800, 500 + 300 * (charts.len() as u32 - 1)), XScale::Linear).unwrap();
        let (boxes, curves) = legends_and_curves(&svg);
        assert_eq!(boxes.len(), charts.len(), "one legend per panel");
        for (x0, y0, x1, y1) in boxes {
            for c in &curves {
                for w in c.windows(2) {
                    for k in 0..=50 {
                        let t = k as f64 / 50.0;
                        let (x, y) = (w[0].0 + t * (w[1].0 - w[0].0), w[0].1 + t * (w[1].1 - w[0].1));
                        assert!(
                            !(x0..=x1).contains(&x) || !(y0..=y1).contains(&y),
                            "{}: the legend ({x0}, {y0})–({x1}, {y1}) covers the curve at ({x}, {y})",
                            charts[0].title
                        );
                    }
                }
            }
        }
    }
}

/// A three-point series (a Bode plot of three sine recordings) has its points marked; a
/// time series of hundreds of points does not.
#[test]
fn a_series_of_few_points_has_them_marked() {
    let chart = |n: usize| Chart {
        title: String::new(),
        x_label: "f [Hz]".into(),
        y_label: "gain [dB]".into(),
        series: vec![Series {
            label: "measured".into(),
            points: (0..n).map(|k| (k as f64, (k as f64).sin())).collect(),
            color: 0,
        }],
        y_range: None,
    };
    let circles = |n| svg(&chart(n), (800, 500)).unwrap().matches("<circle").count();
    assert_eq!(circles(3), 3);
    assert_eq!(circles(400), 0);
}

#[test]
fn a_long_title_is_shortened_at_its_start_to_fit_the_width() {
    let title =
        format!("{}/sine-200Hz-run3.csv — time series", "/home/lab/rig-recordings/november".repeat(4));
    let chart = Chart {
        title: title.clone(),
        x_label: "time [s]".into(),
        y_label: "displacement [µm]".into(),
        series: vec![Series { label: "m".into(), points: vec![(0.0, 0.0), (1.0, 1.0)], color: 0 }],
        y_range: None,
    };
    let t = texts(&svg(&chart, (800, 500)).unwrap());
    let caption = t.iter().find(|s| s.ends_with("sine-200Hz-run3.csv — time series")).unwrap_or_else(|| {
        panic!("the caption lost its end: {t:?}");
    });
    assert!(caption.starts_with('…') && caption.chars().count() < title.chars().count(), "{caption}");
    // A title that fits is left alone.
    let short = Chart { title: "demo-val1.csv — time series".into(), ..chart };
    assert!(texts(&svg(&short, (800, 500)).unwrap()).contains(&"demo-val1.csv — time series".to_string()));
}

#[test]
fn stacked_panels_make_one_svg_document() {
    let panel = |y: &str| Chart {
        title: String::new(),
        x_label: "frequency [Hz]".into(),
        y_label: y.into(),
        series: vec![Series { label: "m".into(), points: vec![(100.0, 0.5), (2000.0, 0.9)], color: 0 }],
        y_range: None,
    };
    let svg =
        svg_panels(&[panel("gain"), panel("phase"), panel("coherence")], (900, 760), XScale::Log).unwrap();
    assert!(svg.starts_with("<svg") && svg.matches("<svg").count() == 1, "{svg:.200}");
    let end = svg.rfind("</svg>").unwrap();
    assert!(svg[end + "</svg>".len()..].trim().is_empty(), "text after </svg>");
    assert_eq!(svg.matches("</svg>").count(), 1);
    assert!(svg.find("coherence").unwrap() < end);
}

#[test]
fn bars_stand_in_their_groups_in_proportion_to_their_values() {
    let b = Bars {
        title: "error as effects are added".into(),
        y_label: "mean NRMSE [%]".into(),
        categories: vec!["ja".into(), "ja+mech".into(), "eddy+ja+mech".into()],
        series: vec![
            ("fit".into(), vec![Some(10.04), Some(3.1), Some(1.7)], 2),
            ("validation".into(), vec![Some(11.2), None, Some(1.83)], 1),
        ],
        value_format: |v| format!("{v:.1} %"),
    };
    let svg = bars_svg(&b, (760, 340)).unwrap();
    // (x, height) of the rectangles filled in a palette colour, legend swatch (12 px) left out.
    let bars = |c: RGBColor| -> Vec<(f64, f64)> {
        let fill = format!("fill=\"#{:02X}{:02X}{:02X}\"", c.0, c.1, c.2);
        let attr = |r: &str, name: &str| -> f64 {
            let at = r.find(&format!(" {name}=\"")).unwrap() + name.len() + 3;
            r[at..].split('"').next().unwrap().parse().unwrap()
        };
        svg.split("<rect")
            .filter(|r| r.split('>').next().unwrap().contains(&fill))
            .map(|r| (attr(r, "x"), attr(r, "height")))
            .filter(|(_, h)| *h != 10.0)
            .collect()
    };
    let (fit, val) = (bars(PALETTE[2]), bars(PALETTE[1]));
    assert_eq!((fit.len(), val.len()), (3, 2), "one bar per value: {fit:?} {val:?}");
    // Heights in proportion to the values (to a pixel), groups left to right, fit before val.
    let scale = fit[0].1 / 10.04;
    for ((_, h), v) in fit.iter().zip([10.04, 3.1, 1.7]) {
        assert!((h - v * scale).abs() <= 1.0, "bar of {v}: {h} px");
    }
    assert!((val[0].1 - 11.2 * scale).abs() <= 1.0 && (val[1].1 - 1.83 * scale).abs() <= 1.0);
    assert!(fit[0].0 < val[0].0 && val[0].0 < fit[1].0 && fit[2].0 < val[1].0, "{fit:?} {val:?}");
}
