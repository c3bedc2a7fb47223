//! The viewer's control panels on the left, one method per collapsible section: each edits
//! the app's [`ViewState`] and says what changed; none waits for a frame.

// The panels edit the app: its types and imports are theirs.
use super::*;

impl ViewerApp {
    pub(super) fn controls(&mut self, ui: &mut egui::Ui) {
        type Section = (&'static str, bool, fn(&mut ViewerApp, &mut egui::Ui));
        let sections: [Section; 6] = [
            ("Data and time", true, Self::time_controls),
            ("Transfer functions", true, Self::map_controls),
            ("Camera", false, Self::camera_controls),
            ("Lighting and quality", true, Self::quality_controls),
            ("Backend", true, Self::backend_controls),
            ("State", true, Self::state_controls),
        ];
        for (name, open, show) in sections {
            egui::CollapsingHeader::new(name)
                .default_open(open)
                .show(ui, |ui| show(self, ui));
        }
    }

    fn time_controls(&mut self, ui: &mut egui::Ui) {
        ui.label(self.source.path.display().to_string());
        let len = self.series.len();
        let count = self
            .series
            .step_info(self.state.step)
            .map_or(0, |i| i.count);
        ui.label(format!("{len} steps · {count} particles in this step"));
        // Where the data records times, the slider says the step's.
        let label = match self.series.times().and_then(|t| t.get(self.state.step)) {
            Some(time) => format!("step (time {time})"),
            None => "step".to_owned(),
        };
        ui.add_enabled(
            len > 1,
            egui::Slider::new(&mut self.state.step, 0..=len.saturating_sub(1)).text(label),
        );
        ui.horizontal(|ui| {
            if ui.button("previous").clicked() && self.state.step > 0 {
                self.state.step -= 1;
            }
            let play_label = if self.playing.is_some() {
                "pause"
            } else {
                "play"
            };
            if ui.button(play_label).clicked() {
                self.playing = match self.playing {
                    Some(_) => None,
                    None => Some(true),
                };
                self.last_step_at = Instant::now();
            }
            if ui.button("next").clicked() && self.state.step + 1 < len {
                self.state.step += 1;
            }
            ui.checkbox(&mut self.looping, "loop");
        });
        ui.add(
            egui::Slider::new(&mut self.rate, 0.5..=60.0)
                .logarithmic(true)
                .text("steps / s"),
        );
        ui.separator();
        let mut attribute = self.state.field.attribute.clone();
        egui::ComboBox::new("attribute", "attribute")
            .selected_text(attribute.clone().unwrap_or_else(|| "(density only)".into()))
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut attribute, None, "(density only)");
                for a in &self.attributes_in_data {
                    ui.selectable_value(&mut attribute, Some(a.clone()), a);
                }
            });
        if attribute != self.state.field.attribute {
            self.change_attribute(attribute);
        }
        let previous = self.range_mode;
        ui.horizontal(|ui| {
            ui.label("range");
            ui.radio_value(&mut self.range_mode, RangeMode::Series, "series");
            ui.radio_value(&mut self.range_mode, RangeMode::Step, "this step");
            ui.radio_value(&mut self.range_mode, RangeMode::Fixed, "fixed");
        })
        .response
        .on_hover_text("the range the colour map spans: the least to the largest value");
        ui.horizontal(|ui| {
            ui.label("robust");
            ui.radio_value(&mut self.range_mode, RangeMode::Robust, "series 1-99%");
            ui.radio_value(
                &mut self.range_mode,
                RangeMode::RobustStep,
                "this step 1-99%",
            );
        })
        .response
        .on_hover_text(
            "the 1st to the 99th percentile: a few outliers do not wash the rest into one colour",
        );
        let histogram = self.shown.histogram.clone();
        match self.range_mode {
            RangeMode::Series => self.state.field.attribute_range = None,
            RangeMode::Step => {
                if let Some(h) = &histogram
                    && (previous != RangeMode::Step || self.state.field.attribute_range.is_none())
                {
                    self.state.field.attribute_range = Some(h.step_range);
                }
            }
            RangeMode::Robust => {
                self.state.field.attribute_range = self.series_attribute().map(|a| (a.p01, a.p99));
            }
            RangeMode::RobustStep => {
                if let Some(h) = &histogram
                    && (previous != RangeMode::RobustStep
                        || self.state.field.attribute_range.is_none())
                {
                    self.state.field.attribute_range = Some(h.step_robust_range);
                }
            }
            RangeMode::Fixed => {
                let series_range = self
                    .series_attribute()
                    .map_or((0.0, 1.0), |a| (a.min, a.max));
                let (mut lo, mut hi) = self.state.field.attribute_range.unwrap_or(series_range);
                ui.horizontal(|ui| {
                    let speed = ((hi - lo).abs() * 0.002).max(1e-9);
                    let from = ui.label("from").id;
                    ui.add(egui::DragValue::new(&mut lo).speed(speed))
                        .labelled_by(from);
                    let to = ui.label("to").id;
                    ui.add(egui::DragValue::new(&mut hi).speed(speed))
                        .labelled_by(to);
                });
                if lo < hi {
                    self.state.field.attribute_range = Some((lo, hi));
                }
            }
        }
    }

    fn map_controls(&mut self, ui: &mut egui::Ui) {
        let histogram = self.shown.histogram.clone();
        let histogram = histogram.as_deref();
        let mut colormap = self.state.colormap.clone();
        ui.horizontal(|ui| {
            egui::ComboBox::new("colormap", "colour map")
                .selected_text(&colormap)
                .show_ui(ui, |ui| {
                    for p in PRESETS {
                        ui.selectable_value(&mut colormap, p.to_owned(), p);
                    }
                });
        });
        ui.horizontal(|ui| {
            let label = ui.label("ParaView .json").id;
            ui.add(egui::TextEdit::singleline(&mut self.paraview_path).desired_width(130.0))
                .labelled_by(label);
            if ui.button("import").clicked() {
                colormap = self.paraview_path.clone();
            }
        });
        if colormap != self.state.colormap {
            match ColorMap::from_name_or_file(&colormap) {
                Ok(map) => {
                    self.state.field.color_map = map;
                    self.state.colormap = colormap;
                }
                Err(e) => self.say(format!("colour map {colormap}: {e}")),
            }
        }
        let has_attribute = self.state.field.attribute.is_some();
        ui.add_enabled_ui(has_attribute, |ui| {
            ui.horizontal(|ui| {
                ui.label("classification");
                ui.radio_value(
                    &mut self.state.field.classification,
                    Classification::Post,
                    "post",
                );
                ui.radio_value(
                    &mut self.state.field.classification,
                    Classification::Pre,
                    "pre",
                );
            });
            ui.checkbox(
                &mut self.state.settings.colour_by_density,
                "colour by density",
            );
            ui.checkbox(&mut self.log_y, "histogram log scale");
            ui.checkbox(&mut self.show_legend, "colour legend");
            ui.label("density map w(t)");
            let mut density = self.state.field.density_map.0.clone();
            let top = density.max_value().max(1.0);
            if map_editor(ui, "density map", &mut density, top, histogram, self.log_y) {
                match DensityMap::new(density) {
                    Ok(m) => self.state.field.density_map = m,
                    Err(e) => self.say(e.to_string()),
                }
            }
            ui.label("radius map m(t)");
            let mut radius = self.state.field.radius_map.0.clone();
            if map_editor(ui, "radius map", &mut radius, 1.0, histogram, self.log_y) {
                match RadiusMap::new(radius) {
                    Ok(m) => self.state.field.radius_map = m,
                    Err(e) => self.say(e.to_string()),
                }
            }
        });
        let diagonal = view_bounds(self.series.bounds()).diagonal();
        ui.add(
            egui::Slider::new(
                &mut self.state.field.radius,
                diagonal * 1e-5..=diagonal * 0.2,
            )
            .logarithmic(true)
            .text("radius"),
        );
        ui.label("optical density D(Phi / Phi_ref)");
        let mut optical = self.state.settings.optical.map().clone();
        let top = optical.max_value().max(1.0);
        let changed = map_editor(ui, "optical density map", &mut optical, top, None, false);
        let used_scale = self.shown.used.map(|u| u.density_scale);
        let mut scale = self.state.settings.optical.scale();
        ui.horizontal(|ui| {
            let mut automatic = scale.is_none();
            let label = ui.checkbox(&mut automatic, "automatic scale").id;
            if automatic {
                scale = None;
                if let Some(s) = used_scale {
                    ui.label(format!("{s:.3e}"));
                }
            } else {
                let mut v = scale.or(used_scale).unwrap_or(1.0);
                let speed = v * 0.01;
                ui.add(
                    egui::DragValue::new(&mut v)
                        .speed(speed)
                        .range(1e-12..=1e12),
                )
                .labelled_by(label);
                scale = Some(v);
            }
        });
        if changed || scale != self.state.settings.optical.scale() {
            match OpticalDensityMap::new(optical, scale) {
                Ok(m) => self.state.settings.optical = m,
                Err(e) => self.say(e.to_string()),
            }
        }
    }

    fn camera_controls(&mut self, ui: &mut egui::Ui) {
        let bounds = view_bounds(self.series.bounds());
        let mut camera = self.state.camera();
        ui.horizontal_wrapped(|ui| {
            if ui.button("reset").clicked() {
                camera = Camera {
                    fovy: camera.fovy,
                    ..Camera::default_for(bounds)
                };
            }
            for v in AxisView::ALL {
                if ui.button(v.label()).clicked() {
                    camera = v.camera(bounds, camera.fovy);
                }
            }
        });
        ui.add(egui::Slider::new(&mut camera.fovy, 5.0..=120.0).text("field of view °"));
        ui.label("drag: rotate · right drag or shift-drag: pan · wheel: zoom");
        if camera != self.state.camera() {
            self.state.settings.camera = Some(camera);
        }
    }

    fn quality_controls(&mut self, ui: &mut egui::Ui) {
        let s = &mut self.state.settings;
        let method = method_controls(ui, s);
        let splatting = method == Method::Splat;
        ui.add_enabled_ui(!splatting, |ui| {
            egui::ComboBox::new("integrator", "integrator")
                .selected_text(integrator_name(s.integrator))
                .show_ui(ui, |ui| {
                    for i in [
                        Integrator::Ea,
                        Integrator::Delta,
                        Integrator::Marching,
                        Integrator::SsReference,
                    ] {
                        ui.selectable_value(&mut s.integrator, i, integrator_name(i));
                    }
                });
        });
        let scattering = s.integrator != Integrator::Ea && !splatting;
        ui.add_enabled_ui(scattering, |ui| {
            ui.add(egui::Slider::new(&mut s.light.azimuth, -180.0..=180.0).text("light azimuth °"));
            ui.add(
                egui::Slider::new(&mut s.light.elevation, -90.0..=90.0).text("light elevation °"),
            );
            ui.add(egui::Slider::new(&mut s.light.intensity, 0.0..=10.0).text("light intensity"));
            ui.add(egui::Slider::new(&mut s.light.ambient, 0.0..=2.0).text("ambient"));
        });
        ui.horizontal(|ui| {
            ui.label("noise");
            ui.radio_value(&mut s.noise, NoiseKind::Stbn, "blue (STBN)");
            ui.radio_value(&mut s.noise, NoiseKind::White, "white");
        });
        step_size_controls(ui, s, self.shown.used.map(|u| u.step_size));
        ui.add(
            egui::Slider::new(&mut self.state.spp, 1..=4096)
                .logarithmic(true)
                .text("spp target"),
        );
        let mut k = self.state.cluster;
        egui::ComboBox::new("cluster", "cluster size K")
            .selected_text(k.to_string())
            .show_ui(ui, |ui| {
                for c in ClusterSize::ALL {
                    ui.selectable_value(&mut k, c, c.to_string());
                }
            });
        self.state.cluster = k;
        let mut precision = self.state.precision.clone();
        egui::ComboBox::new("precision", "precision")
            .selected_text(precision.clone())
            .show_ui(ui, |ui| {
                for (value, meaning) in PRECISIONS {
                    ui.selectable_value(&mut precision, value.to_owned(), value)
                        .on_hover_text(meaning);
                }
            })
            .response
            .on_hover_text("how positions are held and the field computed (the backend panel says what the scene got)");
        self.state.precision = precision;
    }

    fn backend_controls(&mut self, ui: &mut egui::Ui) {
        let mut kind = self.state.backend;
        egui::ComboBox::new("backend", "backend")
            .selected_text(kind.to_string())
            .show_ui(ui, |ui| {
                for b in BACKENDS {
                    ui.selectable_value(&mut kind, b, b.to_string());
                }
            });
        self.state.backend = kind;
        let s = &self.shown;
        if let Some((name, device)) = &s.backend {
            ui.label(format!("{name} on {device}"));
        }
        if let Some(p) = &s.positions {
            ui.label(format!("positions: {p}"));
        }
        let t = s.timings;
        ui.label(format!(
            "prepare {:.1} ms (CPU) + {:.1} ms (device) · upload {:.1} ms · build {:.1} ms · \
             refit {:.1} ms",
            ms(t.prepare),
            ms(t.device_prepare),
            ms(t.upload),
            ms(t.build),
            ms(t.refit)
        ));
        let m = s.memory;
        ui.label(format!(
            "memory: particles {:.1} MiB · structure {:.1} MiB · image {:.1} MiB · step \
             preparation {:.1} MiB",
            mib(m.particle_bytes),
            mib(m.structure_bytes),
            mib(m.image_bytes),
            mib(m.preparation_bytes)
        ));
        ui.label(format!(
            "image to window: {:.1} ms per update (readback and conversion)",
            ms(s.readback)
        ));
    }

    fn state_controls(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            let label = ui.label("scene file").id;
            ui.add(egui::TextEdit::singleline(&mut self.scene_path).desired_width(150.0))
                .labelled_by(label);
            if ui.button("save").clicked() {
                let path = PathBuf::from(&self.scene_path);
                if let Err(e) = self.save_scene(&path) {
                    self.say(e);
                }
            }
            if ui.button("load").clicked() {
                let path = PathBuf::from(&self.scene_path);
                if let Err(e) = self.load_scene(&path) {
                    self.say(e);
                }
            }
        });
        ui.horizontal(|ui| {
            let label = ui.label("image file").id;
            ui.add(egui::TextEdit::singleline(&mut self.screenshot_path).desired_width(150.0))
                .labelled_by(label);
            if ui.button("screenshot").clicked() {
                self.worker.screenshot(PathBuf::from(&self.screenshot_path));
            }
        });
        if let Some(last) = self.shown.screenshots.last() {
            ui.label(format!("wrote {}", last.display()));
        }
    }
}

/// The renderer: the paper's RBF, or a Table 3 baseline, to look at their artefacts beside
/// the RBF image, with the baseline's own setting.
fn method_controls(ui: &mut egui::Ui, s: &mut crate::render::RenderSettings) -> Method {
    let mut method = match (s.splat_k, s.voxel_grid) {
        (Some(_), _) => Method::Splat,
        (None, Some(_)) => Method::Voxel,
        (None, None) => Method::Rbf,
    };
    egui::ComboBox::new("method", "renderer")
        .selected_text(method_name(method))
        .show_ui(ui, |ui| {
            for m in [Method::Rbf, Method::Voxel, Method::Splat] {
                ui.selectable_value(&mut method, m, method_name(m));
            }
        })
        .response
        .on_hover_text(
            "RBF: the particles queried at every sample (the paper's method). Voxel grid: \
             the particles splatted into a grid, re-voxelised on every change, then \
             marched. Splat: each ray cut into slabs one step long, at most k particles a \
             slab, sorted and composited front to back (emission-absorption).",
        );
    (s.splat_k, s.voxel_grid) = match method {
        Method::Rbf => (None, None),
        Method::Voxel => {
            let mut n = s.voxel_grid.unwrap_or(crate::render::VOXEL_GRID);
            ui.add(
                egui::Slider::new(&mut n, 8..=crate::backend::voxel::MAX_GRID)
                    .logarithmic(true)
                    .text("cells along the longest side"),
            );
            (None, Some(n))
        }
        Method::Splat => {
            let mut k = s.splat_k.unwrap_or(crate::render::SPLAT_K);
            ui.add(
                egui::Slider::new(
                    &mut k,
                    1..=crate::values::shader_constants::SPLAT_K_MAX as usize,
                )
                .text("hits per slab"),
            );
            (Some(k), None)
        }
    };
    method
}

/// The march's step: automatic (showing the one the image used) or set by hand.
fn step_size_controls(
    ui: &mut egui::Ui,
    s: &mut crate::render::RenderSettings,
    used_step: Option<f64>,
) {
    ui.horizontal(|ui| {
        let mut automatic = s.step_size.is_none();
        let label = ui.checkbox(&mut automatic, "automatic step").id;
        if automatic {
            s.step_size = None;
            if let Some(dt) = used_step {
                ui.label(format!("{dt:.3e}"));
            }
        } else {
            let mut dt = s.step_size.or(used_step).unwrap_or(1e-2);
            let speed = dt * 0.01;
            ui.add(
                egui::DragValue::new(&mut dt)
                    .speed(speed)
                    .range(1e-12..=1e12),
            )
            .labelled_by(label);
            s.step_size = Some(dt);
        }
    });
}
