//
// pbrt scenes through Yocto/SceneIO: what the pbrt importer keeps (UTF-8
// names) saves as json. The pbrt tests proper are in test_pbrtio.cpp.
//

#include <yocto/yocto_sceneio.h>

#include "test_pbrtio.h"

TEST(pbrtio, strings_must_be_utf8) {
  auto dir = temp_dir{};
  // Latin-1, a lone continuation byte, an overlong '/', a surrogate, a code
  // point past U+10FFFF and a sequence cut short by the closing quote.
  for (auto bad : {"caf\xe9", "\x80", "\xc0\xaf", "\xed\xa0\x80", "\xf4\x90\x80\x80", "x\xe2\x82"}) {
    expect_error(dir,
        "WorldBegin\nMakeNamedMaterial \"" + std::string{bad} +
            "\" \"string type\" \"diffuse\"\nShape \"sphere\"\n",
        {"scene.pbrt:2: string \"", "\" is not valid UTF-8 (byte 0x"});
  }
  expect_error(dir, "WorldBegin\nShape \"sphere\" \"string note\" \"\xff\"\n",
      {"scene.pbrt:2:", "not valid UTF-8 (byte 0xFF at offset 0"});
  // Valid UTF-8 names of 2, 3 and 4 bytes are kept and save as json.
  auto name  = std::string{"caf\xc3\xa9 \xe6\x97\xa5 \xf0\x9f\x98\x80"};
  auto scene = scene_data{};
  auto error = std::string{};
  ASSERT_TRUE(load_text(dir,
      "WorldBegin\nMakeNamedMaterial \"" + name + "\" \"string type\" \"diffuse\"\n"
      "NamedMaterial \"" + name + "\"\nShape \"sphere\"\n",
      scene, error))
      << error;
  EXPECT_EQ(scene.material_names.at(0), name);
  EXPECT_TRUE(save_scene(dir / "saved.json", scene, error)) << error;
}
