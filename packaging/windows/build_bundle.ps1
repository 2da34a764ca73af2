# Build the Windows one-folder bundle (dist\workbench\workbench.exe) -- NOT TESTED:
# written on Linux, no Windows machine was available.
#
#   powershell -ExecutionPolicy Bypass -File packaging\windows\build_bundle.ps1 [-SoftwareGL]
#
# Needs a python.org Python >= 3.11 (64-bit) as `py -3.11` or on PATH.
# Output: build\windows\dist\workbench\ (zip it, or wrap it in an installer:
# see packaging\README.md, "Windows").
# -SoftwareGL also copies Qt's Mesa llvmpipe opengl32sw.dll beside workbench.exe
# as opengl32.dll, so the 3D views work on machines without OpenGL 3.2
# (virtual machines, remote desktop): slower, but it always draws.
param([switch]$SoftwareGL)
$ErrorActionPreference = "Stop"
$root = Resolve-Path (Join-Path $PSScriptRoot "..\..")
$out = Join-Path $root "build\windows"
$venv = Join-Path $out "venv"
$python = Join-Path $venv "Scripts\python.exe"

Remove-Item -Recurse -Force -ErrorAction SilentlyContinue (Join-Path $out "dist"), (Join-Path $out "work"), (Join-Path $out "wheel")
New-Item -ItemType Directory -Force $out | Out-Null
if (-not (Test-Path $python)) { py -3.11 -m venv $venv }
& $python -m pip install -q --upgrade pip
& $python -m pip install -q -r (Join-Path $root "packaging\pyinstaller\requirements.txt")
& $python -m build --wheel --outdir (Join-Path $out "wheel") $root
# (not installed yet is fine: stderr of a native command must not stop the script)
$ErrorActionPreference = "Continue"
& $python -m pip uninstall -q -y forensic-workbench 2>&1 | Out-Null
$ErrorActionPreference = "Stop"
$wheel = Get-ChildItem (Join-Path $out "wheel\*.whl") | Select-Object -First 1
& $python -m pip install -q $wheel.FullName -c (Join-Path $root "packaging\constraints.txt")
if ($LASTEXITCODE -ne 0) { throw "pip install failed" }

# the icon: a multi-size .ico rendered from the SVG
$icon = Join-Path $out "workbench.ico"
& $python (Join-Path $root "packaging\make_icon.py") --ico $icon

# PyInstaller from outside the checkout, so the installed wheel is what gets bundled
Push-Location $out
$env:WORKBENCH_ICON = $icon
& (Join-Path $venv "Scripts\pyinstaller.exe") --noconfirm --log-level WARN `
    --distpath (Join-Path $out "dist") --workpath (Join-Path $out "work") `
    (Join-Path $root "packaging\pyinstaller\workbench.spec")
if ($LASTEXITCODE -ne 0) { throw "pyinstaller failed" }
Pop-Location
$bundle = Join-Path $out "dist\workbench"
$exe = Join-Path $bundle "workbench.exe"

# OpenGL fallback: PySide6 ships Mesa's llvmpipe as opengl32sw.dll (Qt uses it
# with QT_OPENGL=software); VTK draws through opengl32.dll, which Windows looks
# for in the program's folder first.
$sw = Get-ChildItem -Recurse (Join-Path $bundle "_internal") -Filter opengl32sw.dll | Select-Object -First 1
if ($null -eq $sw) {
    Write-Warning "opengl32sw.dll is not in the bundle: no software OpenGL fallback (see packaging\README.md)"
} elseif ($SoftwareGL) {
    Copy-Item $sw.FullName (Join-Path $bundle "opengl32.dll")
    Set-Content (Join-Path $bundle "workbench-software-gl.cmd") "@set QT_OPENGL=software`r`n@`"%~dp0workbench.exe`" %*"
}

# smoke test: version, the demo, the window (a picture of it)
Push-Location $env:TEMP
& $exe --version
if ($LASTEXITCODE -ne 0) { throw "workbench --version failed" }
& $exe demo --out (Join-Path $env:TEMP "workbench-bundle-demo") --force --skip-headsq
if ($LASTEXITCODE -ne 0) { throw "workbench demo failed" }
& $exe gui --screenshot (Join-Path $env:TEMP "workbench-bundle-window.png")
if ($LASTEXITCODE -ne 0) { throw "workbench gui failed" }
Pop-Location
$size = (Get-ChildItem -Recurse $bundle | Measure-Object -Property Length -Sum).Sum / 1MB
Write-Output ("built {0} ({1:N0} MB)" -f $bundle, $size)
