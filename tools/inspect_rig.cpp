// facecap inspect-rig: what a rig contains, for an operator checking a new face.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <optional>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "solver/fbx_rig.hpp"
#include "solver/rig.hpp"
#include "tools/commands.hpp"

namespace facecap::tools {

void add_inspect_rig_command(CLI::App& app, int& exit_code) {
  struct Options {
    std::string rig;
    bool json = false;
    bool no_cache = false;
  };
  auto opts = std::make_shared<Options>();
  auto* cmd = app.add_subcommand("inspect-rig", "Show a rig's vertices, triangles, shapes, size and units");
  cmd->add_option("rig", opts->rig, "builtin, an OBJ directory, a rig.toml manifest, a .gltf/.glb or an .fbx file")->required();
  cmd->add_flag("--json", opts->json, "Print JSON instead of text");
  cmd->add_flag("--no-cache", opts->no_cache, "Parse the files even when a cached copy exists");
  cmd->callback([opts, &exit_code] {
    RigLoadOptions load_options;
    load_options.use_cache = !opts->no_cache;
    RigLoadReport report;
    // An FBX is read afresh, bypassing the cache, to say what the file holds and what
    // welding its seam-split vertices did.
    std::optional<FbxContents> fbx;
    const Rig rig = [&] {
      if (!is_fbx_path(opts->rig)) return load_rig(opts->rig, load_options, &report);
      const auto start = std::chrono::steady_clock::now();
      fbx.emplace();
      Rig loaded = load_fbx_rig(opts->rig, &*fbx);
      loaded.source = std::filesystem::absolute(opts->rig).string();
      report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      return loaded;
    }();
    const BoundingBox box = bounding_box(rig.neutral);
    const std::string units = guess_face_units(box);
    const Eigen::VectorXd displacement = max_shape_displacement(rig);
    if (opts->json) {
      nlohmann::json j;
      j["name"] = rig.name;
      j["source"] = rig.source;
      j["vertices"] = rig.vertex_count();
      j["triangles"] = rig.triangle_count();
      j["shapes"] = rig.shape_count();
      j["shape_names"] = rig.shape_names;
      j["bbox"] = {{"min", {box.min.x(), box.min.y(), box.min.z()}},
                   {"max", {box.max.x(), box.max.y(), box.max.z()}},
                   {"size", {box.size().x(), box.size().y(), box.size().z()}}};
      j["units_guess"] = units;
      nlohmann::json per_shape = nlohmann::json::object();
      for (Eigen::Index s = 0; s < rig.shape_count(); ++s) per_shape[rig.shape_names[std::size_t(s)]] = displacement[s];
      j["max_displacement"] = per_shape;
      j["content_hash"] = fmt::format("{:016x}", rig.content_hash());
      if (fbx) {
        nlohmann::json meshes = nlohmann::json::array();
        for (const auto& m : fbx->meshes)
          meshes.push_back({{"name", m.name}, {"vertices", m.vertices}, {"faces", m.faces}, {"channels", m.channels}});
        j["fbx"] = {{"meshes", meshes}, {"rig_mesh", fbx->rig_mesh},
                    {"vertices_before_weld", fbx->vertices_before_weld}, {"vertices_after_weld", fbx->vertices_after_weld}};
      }
      j["load"] = {{"seconds", report.seconds}, {"from_cache", report.from_cache},
                   {"cache_file", report.cache_file.string()}};
      std::puts(j.dump(2).c_str());
      return;
    }
    fmt::print("rig        {}  ({})\n", rig.name, rig.source);
    fmt::print("vertices   {}\ntriangles  {}\nshapes     {}\n", rig.vertex_count(), rig.triangle_count(), rig.shape_count());
    fmt::print("bbox       min ({:.3f}, {:.3f}, {:.3f})  max ({:.3f}, {:.3f}, {:.3f})  size {:.3f} x {:.3f} x {:.3f}\n",
               box.min.x(), box.min.y(), box.min.z(), box.max.x(), box.max.y(), box.max.z(), box.size().x(),
               box.size().y(), box.size().z());
    fmt::print("units      {} (guessed from the face's size)\n", units);
    if (fbx) {
      for (std::size_t m = 0; m < fbx->meshes.size(); ++m) {
        const auto& mesh = fbx->meshes[m];
        fmt::print("fbx mesh   '{}': {} vertices, {} faces, {} blendshape channels{}\n", mesh.name, mesh.vertices,
                   mesh.faces, mesh.channels, m == fbx->rig_mesh ? "  <- the rig" : "");
      }
      fmt::print("welded     {} vertices split at seams -> {}\n", fbx->vertices_before_weld, fbx->vertices_after_weld);
    }
    fmt::print("loaded in  {:.3f} s{}\n", report.seconds, report.from_cache ? " (from cache)" : "");
    fmt::print("\n{:<24} {:>12}\n", "shape", "max move");
    for (Eigen::Index s = 0; s < rig.shape_count(); ++s)
      fmt::print("{:<24} {:>12.4f}\n", rig.shape_names[std::size_t(s)], displacement[s]);
    exit_code = 0;
  });
}

}  // namespace facecap::tools
