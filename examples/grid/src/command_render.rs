//! `fogray-grid render`: a saved model rendered from the ring's views, beside the exact
//! photographs.

use super::*;
use crate::command_fit::saved_scene;

#[derive(Serialize)]
struct RenderSummary {
    images: Vec<Vec<Vec<Vec<f64>>>>,
    views: Vec<usize>,
    psnr: Vec<f64>,
}

pub(crate) fn run_render(args: RenderArgs) -> Result<()> {
    let info = checkpoint::read_info(&args.model)?;
    let saved_ring = RingArgs::saved(&info.extra, &args.model)?;
    let ring = RingArgs {
        views: args.views.unwrap_or(saved_ring.views),
        test_views: args.test_views.unwrap_or(saved_ring.test_views),
        size: args.size.unwrap_or(saved_ring.size),
    }
    .ring()?;
    let scene = match &args.scene {
        Some(path) => Scene::read(path)?,
        None => saved_scene(&info.extra, &args.model)?,
    };
    let views = if args.all {
        (0..ring.len()).collect()
    } else if args.view.is_empty() {
        ring.test_views()
    } else {
        args.view.clone()
    };
    if let Some(&bad) = views.iter().find(|&&v| v >= ring.len()) {
        anyhow::bail!(
            "--view {bad} is out of range: the ring has views 0 to {}",
            ring.len() - 1
        );
    }
    if views.is_empty() {
        anyhow::bail!("no view to render: the ring has no test views; pass --view I or --all");
    }
    let kind = FieldKind::of_kind(&info.kind).with_context(|| {
        format!(
            "{}: a {:?} model, which fogray-grid does not know",
            args.model.display(),
            info.kind
        )
    })?;
    create_dir(&args.out)?;
    let work = RenderWork {
        args: &args,
        ring: &ring,
        scene: &scene,
        views: &views,
    };
    with_field_kind(info.settings.precision, kind, work)
}

/// The views to render from the model file, as fogray-fit's dispatch runs it.
struct RenderWork<'a> {
    args: &'a RenderArgs,
    ring: &'a Ring,
    scene: &'a Scene,
    views: &'a [usize],
}

impl FieldWork for RenderWork<'_> {
    type Output = Result<()>;

    fn run<F: fogray::tape::Float, M: RadianceField<F>>(self) -> Result<()> {
        let saved = checkpoint::load::<F, M>(&self.args.model)?;
        let occupancy = saved.occupancy_grid()?;
        let model = saved.start.model;
        let options = RenderOptions {
            background: self.scene.background,
            method: fogray::fit::settings::Method::Fused,
            depth: true,
        };
        // PNGs of about 256 pixels a side whatever the image size.
        let scale = (256 / self.ring.size()).clamp(1, 16) as u32;
        let mut summary = RenderSummary {
            images: Vec::new(),
            views: self.views.to_vec(),
            psnr: Vec::new(),
        };
        for &view in self.views {
            let camera = self.ring.camera(view)?;
            let view_data =
                fogray::fit::dataset::View::new(view.to_string(), &camera, photograph(self.scene, &camera))?;
            let (origins, directions) = view_data.rays();
            let r = render_picture(
                &model,
                occupancy.as_ref(),
                &origins,
                &directions,
                view_data.size(),
                &options,
            )?;
            let exact = view_data.image;
            let db = psnr(&[r.color.view()], &[exact.view()])?;
            let image_path = self.args.out.join(format!("view-{view:03}.png"));
            let depth_path = self.args.out.join(format!("depth-{view:03}.png"));
            write_comparison_png(&image_path, exact.view(), r.color.view(), 4.0, scale)?;
            let depth = r.depth.context("a render asked for depth gave none")?;
            let range = write_depth_png(&depth_path, depth.view(), &format!("view {view}"), scale)?;
            if !self.args.json {
                let depth = match range {
                    Some(d) => format!("depth {:.3} to {:.3}", d.near, d.far),
                    None => "no pixel opaque enough for a depth".into(),
                };
                println!(
                    "view {view:>3}{}  PSNR {db:.2} dB  {}  {} ({depth})",
                    if self.ring.is_test(view) { " (test)" } else { "       " },
                    image_path.display(),
                    depth_path.display()
                );
            }
            summary.images.push(nested(r.color.view()));
            summary.psnr.push(db);
        }
        if self.args.json {
            return write_stdout(|w| Ok(serde_json::to_writer(w, &summary)?));
        }
        Ok(())
    }
}
