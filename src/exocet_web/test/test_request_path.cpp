// The path sanitiser: what a request target may name, and the symbolic links that lead out of the served folder.
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "exocet_common/testing/temp_dir.h"
#include "exocet_web/server/request_path.h"

namespace es = exocet_web::server;
using exocet_common::testing::TempDir;

TEST(RequestPath, PlainPathsAndTheIndex) {
  EXPECT_EQ(es::parseRequestTarget("/tiles/21/1055/752.png").relative, "tiles/21/1055/752.png");
  EXPECT_EQ(es::parseRequestTarget("/tiles/21/1055/752.png?r=17").relative, "tiles/21/1055/752.png");
  EXPECT_EQ(es::parseRequestTarget("/").relative, "index.html");
  EXPECT_EQ(es::parseRequestTarget("/leaflet/").relative, "leaflet/index.html");
  EXPECT_EQ(es::parseRequestTarget("/state.js#x").relative, "state.js");
  EXPECT_EQ(es::parseRequestTarget("/a%20b.png").relative, "a b.png");  // an encoded space is a name
  EXPECT_EQ(es::parseRequestTarget("/x..y.png").relative, "x..y.png");  // dots inside a name are not traversal
}

TEST(RequestPath, TraversalAndMalformedTargetsAreRefused) {
  for (const char* target : {"/../etc/passwd",
                             "/tiles/../../etc/passwd",
                             "/tiles/..",
                             "/./index.html",
                             "/%2e%2e/etc/passwd",
                             "/%2E%2E/etc/passwd",
                             "/tiles/%2e%2e%2f%2e%2e%2fetc/passwd",
                             "/.%2e/etc/passwd",
                             "/%2e./etc/passwd",
                             "/tiles%2f..%2f..%2fetc%2fpasswd",
                             "/tiles%2F21",
                             "/..%5c..%5cetc",
                             "/a\\b",
                             "//etc/passwd",
                             "/tiles//21/1/1.png",
                             "etc/passwd",
                             "",
                             "http://example.com/index.html",
                             "/%",
                             "/%2",
                             "/%zz",
                             "/a%00.png",
                             "/a%0a.png"}) {
    const es::RequestPath p = es::parseRequestTarget(target);
    EXPECT_EQ(p.status, 400) << "'" << target << "' was accepted as '" << p.relative << "'";
    EXPECT_FALSE(p.reason.empty()) << target;
  }
  // Hidden and temporary files (a web tile being written is ".<y>.png.partial") are not served.
  EXPECT_EQ(es::parseRequestTarget("/tiles/21/5/.7.png.partial").status, 404);
  EXPECT_EQ(es::parseRequestTarget("/.git/config").status, 404);
}

TEST(RequestPath, SymbolicLinksMayNotLeadOut) {
  TempDir outside_dir;
  std::ofstream(outside_dir.file("secret.txt")) << "secret";
  TempDir dir;
  std::filesystem::create_directories(dir.file("site/tiles"));
  std::ofstream(dir.file("site/index.html")) << "<html></html>";
  std::filesystem::create_symlink(dir.file("site/index.html"), dir.file("site/tiles/inside.html"));
  std::filesystem::create_symlink(outside_dir.file("secret.txt"), dir.file("site/leak.txt"));
  std::filesystem::create_directory_symlink(outside_dir.path(), dir.file("site/outside"));
  std::filesystem::create_directory_symlink("/", dir.file("site/root"));
  std::ofstream(dir.file("sibling.txt")) << "next to the site";
  std::filesystem::create_symlink("../sibling.txt", dir.file("site/sibling.txt"));
  const std::string root = es::canonicalFolder(dir.file("site"));
  ASSERT_FALSE(root.empty());

  const es::ResolvedFile index = es::resolveInside(root, "index.html");
  EXPECT_EQ(index.status, 200);
  EXPECT_EQ(index.path, root + "/index.html");
  const es::ResolvedFile inside = es::resolveInside(root, "tiles/inside.html");
  EXPECT_EQ(inside.status, 200) << inside.reason;  // a link within the folder is fine
  EXPECT_EQ(es::resolveInside(root, "leak.txt").status, 403);
  EXPECT_EQ(es::resolveInside(root, "outside/secret.txt").status, 403);
  EXPECT_EQ(es::resolveInside(root, "root/etc/hostname").status, 403);
  EXPECT_EQ(es::resolveInside(root, "sibling.txt").status, 403);
  EXPECT_EQ(es::resolveInside(root, "missing.png").status, 404);
  EXPECT_EQ(es::resolveInside(root, "tiles").status, 404);          // a folder is not a file
  EXPECT_NE(es::resolveInside(root, "/etc/hostname").status, 200);  // absolute
  // A folder whose name starts like the root's is not inside it ("<root>-other").
  std::filesystem::create_directories(dir.file("site-other"));
  std::ofstream(dir.file("site-other/x.txt")) << "x";
  std::filesystem::create_symlink(dir.file("site-other/x.txt"), dir.file("site/x.txt"));
  EXPECT_EQ(es::resolveInside(root, "x.txt").status, 403);
  EXPECT_EQ(es::canonicalFolder(dir.file("nowhere")), "");
}
