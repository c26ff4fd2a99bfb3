#include "engine/vdb_export.h"

#include <dlfcn.h>

#include <cstdlib>
#include <stdexcept>
#include <system_error>

#include "engine/input/file_util.h"

namespace sf {

std::filesystem::path VdbExporter::plugin_path() {
  if (const char* file = std::getenv("SCALEFUSE_VDB_PLUGIN"); file && *file) return file;
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) throw std::runtime_error("--export-vdb: cannot find the running program (/proc/self/exe: " + ec.message() + ")");
  return exe.parent_path().parent_path() / "lib" / "scalefuse" / "libscalefuse_vdb.so";
}

VdbExporter VdbExporter::load() {
  const std::filesystem::path file = plugin_path();
  void* handle = ::dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!handle) {
    const char* why = ::dlerror();
    // dlerror() names the file
    throw std::runtime_error(std::string("--export-vdb: cannot load the OpenVDB export plugin: ") +
                             (why ? why : file.c_str()));
  }
  VdbExporter exporter;
  exporter.export_ = reinterpret_cast<VdbExportFn>(::dlsym(handle, kVdbExportSymbol));
  if (!exporter.export_)
    throw std::runtime_error(file.string() + ": not the OpenVDB export plugin (no " + kVdbExportSymbol + ")");
  return exporter;
}

void VdbExporter::write(const std::filesystem::path& path, const std::vector<SurfaceVoxel>& voxels,
                        const RootCube& root) const {
  const std::filesystem::path tmp = input_detail::temp_sibling(path);
  char error[1024] = {};
  if (export_(tmp.c_str(), voxels.data(), voxels.size(), &root, error, sizeof error) != 0) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw std::runtime_error(path.string() + ": cannot write VDB: " + error);
  }
  input_detail::commit_temp(tmp, path);
}

}  // namespace sf
